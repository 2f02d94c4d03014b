"""The viewer under hostile input and load: every request answered, bursts queued, slow clients
closed, memory bounded under an episode flood.

The server runs as its own process (the real `ViewerServer` over a real run folder), so the burst
does not share file descriptors and threads with pytest and its memory is its own (/proc/PID/status).
The run folder is the trainer's output: gold-replay episodes written by `write_samples`
(`gold_run`), copied to `ROWS` episodes of one step with distinct sample ids.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import urlsplit

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from tests.raw_http import burst_statuses, memory_kb, send_raw

ROOT = Path(__file__).resolve().parents[2]
ROWS = 400            # episodes in the flooded step file
TIMEOUT_S = 1.0       # the served process's per-connection timeout
SERVE = f"""
import sys
from viewer.data import discover
from viewer.server import ViewerServer
server = ViewerServer(discover(sys.argv[1:]), timeout_s={TIMEOUT_S})
print(server.url, flush=True)
server.serve_forever()
"""


@pytest.fixture(scope="module")
def hostile_run(gold_run, tmp_path_factory):
    source = pq.read_table(gold_run / "trajectories" / "step_000001.parquet")
    copies = []
    for i in range(-(-ROWS // source.num_rows)):
        ids = pc.binary_join_element_wise(source.column("sample_id"), pa.scalar(f"copy{i}"), ":")
        copies.append(source.set_column(source.schema.get_field_index("sample_id"), "sample_id", ids))
    run = tmp_path_factory.mktemp("viewer-hostile") / "run"
    (run / "trajectories").mkdir(parents=True)
    pq.write_table(pa.concat_tables(copies).slice(0, ROWS), run / "trajectories" / "step_000001.parquet")
    (run / "metrics.jsonl").write_text((gold_run / "metrics.jsonl").read_text(encoding="utf-8"), encoding="utf-8")
    return run


@pytest.fixture(scope="module")
def server(hostile_run):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", SERVE, str(hostile_run)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), f"the viewer did not start (exit {proc.poll()})"
        parts = urlsplit(url)
        yield proc, (parts.hostname, parts.port)
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def raw_get(address, target: bytes, timeout: float = 30.0) -> tuple[int, str]:
    """One GET as bytes on a socket: (status, body)."""
    data = send_raw(address, b"GET " + target + b" HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n", timeout)
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), body.decode("utf-8", "replace")


@pytest.mark.parametrize(("target", "status", "named"), [
    (b"/api/episodes?source=s0&step=" + b"9" * 23, 400, "step"),
    (b"/api/episodes?source=s0&min_severity=" + b"9" * 20, 400, "min_severity"),
    (b"/api/episodes?source=s0&offset=" + b"9" * 25, 400, "offset"),
    (b"/api/episodes?source=s0&step=-1", 400, "step"),
    (b"/api/run/episode?source=s0&file=" + b"9" * 30 + b"&row=0", 400, "file"),
    (b"/api/run/episode?source=s0&file=0&row=" + b"9" * 30, 400, "row"),
    (b"/static/" + b"a" * 300, 400, "300 characters"),
    (b"/static/app\x00.js", 400, "NUL"),
    (b"/api/episodes?source=s0&task=a%00b", 400, "'task'"),
    (b"/api/eval/episode?source=s0&row_id=%00", 400, "'row_id'"),
    # what held before: traversal, an oversized request line
    (b"/static/../server.py", 404, "not found"),
    (b"/static/" + b"a" * 70_000, 414, ""),
])
def test_hostile_requests_get_a_status_naming_what_was_wrong(server, target, status, named):
    _, address = server
    got, body = raw_get(address, target)
    assert got == status, body[:300]
    assert named in body, body[:300]
    assert raw_get(address, b"/api/sources")[0] == 200  # and it keeps serving


def test_an_unexpected_error_is_a_500_and_a_busy_server_a_503(hostile_run, caplog):
    from viewer.data import discover
    from viewer.server import ViewerServer

    served = ViewerServer(discover([hostile_run]), max_active=1, busy_wait_s=0.05).start()
    address = served.httpd.server_address[:2]
    try:
        def broken():
            raise RuntimeError("a defect in a route")

        served.app.sources["s0"].metrics = broken
        with caplog.at_level("ERROR", logger="hcgym.viewer"):
            status, body = raw_get(address, b"/api/run/metrics?source=s0")
        assert status == 500 and json.loads(body)["error"] == "internal error: RuntimeError: a defect in a route"
        assert "a defect in a route" in caplog.text  # the traceback is logged
        assert served.slots.acquire(timeout=5)  # the one slot taken: the next request finds none
        try:
            status, body = raw_get(address, b"/api/sources")
        finally:
            served.slots.release()
        assert status == 503 and "busy" in json.loads(body)["error"]
        assert raw_get(address, b"/api/sources")[0] == 200
    finally:
        served.stop()


def test_a_burst_of_1000_connections_is_answered_not_reset(server):
    proc, (host, port) = server
    start = time.perf_counter()
    outcomes = burst_statuses(host, port, b"GET /api/sources HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n", 1000, 15)
    counts = {k: outcomes.count(k) for k in set(outcomes)}
    print(f"burst of 1000: {counts} in {time.perf_counter() - start:.1f} s; server {memory_kb(proc.pid)}")
    assert set(counts) <= {"200", "503"}, counts
    assert counts.get("200", 0) > 0


def test_a_slow_client_is_closed_while_others_are_served(server):
    _, address = server
    slow = socket.create_connection(address, timeout=TIMEOUT_S + 5)
    try:
        slow.sendall(b"GET /api/sour")  # half a request line, then nothing
        start = time.perf_counter()
        for _ in range(3):
            assert raw_get(address, b"/api/sources")[0] == 200
        try:
            closed = slow.recv(1024) == b""
        except ConnectionResetError:
            closed = True
        except TimeoutError:
            closed = False
        waited = time.perf_counter() - start
    finally:
        slow.close()
    assert closed, f"the server kept a half-sent request open {waited:.1f} s (timeout {TIMEOUT_S} s)"
    assert waited < TIMEOUT_S + 2


def test_memory_stays_bounded_under_an_episode_flood(server):
    proc, address = server
    assert raw_get(address, b"/api/run/episode?source=s0&file=0&row=0")[0] == 200
    before = memory_kb(proc.pid)

    def episode(i: int) -> int:
        return raw_get(address, f"/api/run/episode?source=s0&file=0&row={i * 7 % ROWS}".encode())[0]

    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=16) as pool:
        statuses = list(pool.map(episode, range(1000)))
    seconds = time.perf_counter() - start
    after = memory_kb(proc.pid)
    counts = {k: statuses.count(k) for k in set(statuses)}
    grown_mb = (after["VmHWM"] - before["VmHWM"]) / 1024
    print(f"episode flood of 1000 ({ROWS}-row step): {counts} in {seconds:.1f} s; server RSS "
          f"{before['VmRSS'] / 1024:.0f} -> {after['VmRSS'] / 1024:.0f} MB, peak {before['VmHWM'] / 1024:.0f} -> "
          f"{after['VmHWM'] / 1024:.0f} MB, threads {after['Threads']}")
    assert set(counts) <= {200, 503} and counts.get(200, 0) >= 900, counts
    assert grown_mb < 64, f"the server's peak RSS grew {grown_mb:.0f} MB under the flood"


def test_episodes_are_read_from_their_row_group_once(hostile_run, tmp_path, monkeypatch):
    """A file of several row groups: each episode comes from its own group, each group decoded once."""
    import viewer.data as data

    table = pq.read_table(hostile_run / "trajectories" / "step_000001.parquet")
    run = tmp_path / "run"
    (run / "trajectories").mkdir(parents=True)
    pq.write_table(table, run / "trajectories" / "step_000001.parquet", row_group_size=100)
    (source,) = data.discover([run])
    cache = data.RowGroupCache()
    monkeypatch.setattr(data, "EPISODE_CACHE", cache)
    ids = table.column("sample_id").to_pylist()
    for row in (0, 99, 100, 250, ROWS - 1, 5, 260):
        assert source.episode(0, row)["sample_id"] == ids[row]
    assert cache.reads == 4  # rows 0-99, 100-199, 200-299 and 300-399, each once
    with pytest.raises(data.ViewerError, match=f"no row {ROWS} .the file has {ROWS}"):
        source.episode(0, ROWS)
