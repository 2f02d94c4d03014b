"""`hcgym serve --mcp` under hostile input and load: every request answered (a tool error naming what
was wrong, a JSON-RPC error, or an HTTP status with a JSON-RPC error body), never a dropped
connection; a burst of 1,000 connections served or refused with 503; slow clients answered 408 and
closed; memory and the server's records bounded under floods of episodes and sessions; kept-alive
calls not held for a delayed ACK.

The server is `hcgym serve --mcp` in its own process (so the burst does not share file descriptors
with pytest and its memory is its own, from /proc/PID/status), with small limits so the bounds are
reached cheaply. Tool calls go through the official MCP SDK client; what a client library would not
send (broken JSON, NUL bytes in the HTTP head, half-sent requests) goes as bytes on a socket.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from mcp import Client
from mcp_types import CLIENT_CAPABILITIES_META_KEY, PROTOCOL_VERSION_META_KEY

from envs.serve.mcp_server import EPISODE_META_KEY, ServeSettings, build_app, uvicorn_server
from tests.raw_http import burst_statuses, memory_kb, send_raw

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 1.0        # the tight server's request timeout
MAX_FINISHED = 32      # ended episodes whose score is kept
MAX_SESSIONS = 16      # legacy-protocol sessions open at once
MODERN = "2026-07-28"
LEGACY = "2025-06-18"


@pytest.fixture(scope="module")
def server():
    env = {**os.environ, "HCGYM_EMBEDDINGS": "0",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-m", "envs.cli", "serve", "--mcp", "--port", "0", "--no-warmup", "--domain",
         "drug_interaction", "--max-episodes", "16", "--max-finished", str(MAX_FINISHED), "--max-sessions",
         str(MAX_SESSIONS)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        found = re.search(r"http://127\.0\.0\.1:\d+/mcp", line)
        assert found, f"the server did not start (exit {proc.poll()}): {line!r}"
        url = found.group(0)
        parts = urlsplit(url)
        yield proc, url, (parts.hostname, parts.port)
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@pytest.fixture(scope="module")
def tight():
    """In process, limits a test reaches in a second: two in-flight slots, a 0.2 s wait for one, a 1 s
    request timeout (the served process keeps the 10 s default: under a burst on a loaded machine the
    event loop itself can take a second to read a request)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HCGYM_EMBEDDINGS", "0")
        settings = ServeSettings(domains=["drug_interaction"], max_requests=2, busy_wait_s=0.2,
                                 request_timeout_s=TIMEOUT_S)
        guard, _ = build_app(settings)
        served = uvicorn_server(settings, guard)
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        thread = threading.Thread(target=served.run, kwargs={"sockets": [sock]}, daemon=True)
        thread.start()
        try:
            deadline = time.monotonic() + 20
            while not served.started:
                assert time.monotonic() < deadline and thread.is_alive(), "the server did not start"
                time.sleep(0.02)
            yield guard, sock.getsockname()
        finally:
            served.should_exit = True
            thread.join(timeout=10)


def open_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def raw(address, head: bytes, body: bytes = b"", timeout: float = 30.0) -> tuple[int, dict[str, str], bytes]:
    """One request as bytes on a socket: (status, headers, body)."""
    data = send_raw(address, head + body, timeout)
    top, _, payload = data.partition(b"\r\n\r\n")
    lines = top.decode("latin-1").split("\r\n")
    headers = dict(line.split(": ", 1) for line in lines[1:] if ": " in line)
    if headers.get("transfer-encoding") == "chunked":
        payload = dechunk(payload)
    return int(lines[0].split()[1]), {k.lower(): v for k, v in headers.items()}, payload


def dechunk(data: bytes) -> bytes:
    out = b""
    while data:
        size, _, data = data.partition(b"\r\n")
        n = int(size.split(b";")[0] or b"0", 16)
        if n == 0:
            break
        out, data = out + data[:n], data[n + 2:]
    return out


def post_head(address, body_length: int | None, version: str | None = MODERN, method: str = "tools/list",
              extra: bytes = b"") -> bytes:
    host, port = address
    head = (f"POST /mcp HTTP/1.1\r\nHost: {host}:{port}\r\ncontent-type: application/json\r\n"
            "accept: application/json, text/event-stream\r\nconnection: close\r\n").encode()
    if version:
        head += f"mcp-protocol-version: {version}\r\nmcp-method: {method}\r\n".encode()
    if body_length is not None:
        head += f"content-length: {body_length}\r\n".encode()
    return head + extra + b"\r\n"


def post(address, body: bytes, version: str | None = MODERN, method: str = "tools/list", extra: bytes = b"",
         timeout: float = 30.0):
    return raw(address, post_head(address, len(body), version, method, extra), body, timeout)


def rpc(method: str, params: dict | None = None, version: str = MODERN, rid: int = 1) -> bytes:
    params = dict(params or {})
    if version == MODERN:
        params["_meta"] = {**params.get("_meta", {}), PROTOCOL_VERSION_META_KEY: MODERN,
                           CLIENT_CAPABILITIES_META_KEY: {}}
    return json.dumps({"jsonrpc": "2.0", "id": rid, "method": method, "params": params}).encode()


def jsonrpc_error(payload: bytes) -> dict:
    """The JSON-RPC error object of a response body (plain JSON or one SSE event)."""
    text = payload.decode("utf-8")
    if text.startswith("event:"):
        text = next(line[5:] for line in text.splitlines() if line.startswith("data:"))
    message = json.loads(text)
    assert message.get("jsonrpc") == "2.0" and isinstance(message.get("error"), dict), text[:300]
    assert isinstance(message["error"].get("code"), int) and message["error"].get("message"), text[:300]
    return message["error"]


def still_serving(address) -> None:
    status, _, payload = post(address, rpc("tools/list"))
    assert status == 200 and b'"start_episode"' in payload, payload[:300]


def calls(url: str, sequence: list[tuple[str, dict, dict | None]]) -> list:
    """Run tool calls in order over one official-SDK client; a call that starts an episode names it for
    the calls after it (meta `None`)."""
    async def go():
        async with Client(url) as client:
            results, meta = [], {}
            for name, arguments, given in sequence:
                result = await client.call_tool(name, arguments, meta=given if given is not None else meta)
                if name == "start_episode" and not result.is_error:
                    meta = {EPISODE_META_KEY: result.structured_content["episode_id"]}
                results.append(result)
            return results
    return asyncio.run(go())


BIG = 10**30
LONG = 50_000  # under the 100,000-character arguments limit, so the check named is the one met


def test_kept_alive_calls_are_not_held_for_a_delayed_ack(server):
    """The SDK client keeps its connection alive: without TCP_NODELAY on the server's sockets each
    response's body waited for the client's delayed ACK (40 ms minimum on Linux) behind its headers."""
    _, url, _ = server

    async def go() -> list[float]:
        async with Client(url) as client:
            started = await client.call_tool("start_episode", {})
            meta = {EPISODE_META_KEY: started.structured_content["episode_id"]}
            seconds = []
            for _ in range(21):
                t0 = time.perf_counter()
                assert not (await client.call_tool("think", {"thought": "t"}, meta=meta)).is_error
                seconds.append(time.perf_counter() - t0)
            await client.call_tool("finish_episode", {"reason": "token_limit"}, meta=meta)
            return sorted(seconds)
    seconds = asyncio.run(go())
    assert seconds[10] < 0.025, f"median call {seconds[10] * 1e3:.1f} ms"


@pytest.mark.parametrize(("name", "arguments", "meta", "named"), [
    ("start_episode", {"seed": BIG}, {}, "argument 'seed'"),
    ("start_episode", {"seed": -1}, {}, "argument 'seed'"),
    ("start_episode", {"task_id": "t" * LONG}, {}, "argument 'task_id'"),
    ("start_episode", {"domain": "d" * LONG}, {}, "argument 'domain'"),
    ("start_episode", {"split": "s" * LONG}, {}, "argument 'split'"),
    ("start_episode", {"task_id": "di\x00x"}, {}, "argument 'task_id'"),
    ("finish_episode", {"reason": "r" * LONG}, None, "argument 'reason'"),
    ("episode_result", {"episode_id": "e" * LONG}, {}, "argument 'episode_id'"),
    ("think", {"thought": "t"}, {EPISODE_META_KEY: "e" * LONG}, "argument 'episode_id'"),
    ("think", {"thought": "t", "episode_id": "ab\x00cd"}, {}, "'ab\\x00cd'"),
    ("t" * 200, {}, None, "at most 128 characters"),
    ("think\x00", {"thought": "t"}, None, "unknown tool 'think"),
    ("think", {"thought": BIG}, None, "thought"),
    ("think", {"thought": 1e308 * 10}, None, "thought"),
])
def test_hostile_tool_calls_get_a_tool_error_naming_what_was_wrong(server, name, arguments, meta, named):
    _, url, address = server
    needs_episode = meta is None
    sequence = [("start_episode", {}, {})] if needs_episode else []
    results = calls(url, [*sequence, (name, arguments, meta)])
    if needs_episode:
        calls(url, [("finish_episode", {"reason": "token_limit"},
                     {EPISODE_META_KEY: results[0].structured_content["episode_id"]})])
    result = results[-1]
    text = result.content[0].text
    assert result.is_error, text[:300]
    assert named in text, text[:300]
    assert "internal error" not in text and len(text) < 1000, text[:300]  # no echo of a 50,000-character value
    still_serving(address)


def test_nul_bytes_in_a_task_tools_arguments_are_answered(server):
    _, url, address = server
    results = calls(url, [("start_episode", {}, {}), ("lookup_drug", {"name": "warfa\x00rin"}, None),
                          ("check_interaction", {"drugs": ["\x00", "aspirin\x00"]}, None),
                          ("finish_episode", {"reason": "token_limit"}, None)])
    for result in results[1:3]:
        text = result.content[0].text
        assert "internal error" not in text, text[:300]
    assert results[-1].structured_content["done"]
    still_serving(address)


@pytest.mark.parametrize("version", [MODERN, None], ids=["2026-07-28", "legacy"])
@pytest.mark.parametrize(("body", "status"), [
    (b"{not json", 400),
    (b"", 400),
    (b"[" * 100_000 + b"]" * 100_000, 400),
    (b'{"jsonrpc": "2.0", "id": ' + b"9" * 5000 + b', "method": "tools/list"}', 400),
    (b'{"jsonrpc": "2.0", "id": 1, "method": "tools/\xff\xfelist"}', 400),
    (b'{"jsonrpc": "2.0", "id": 1, "method": "tools\x00list"}', 400),
    (b'[{"jsonrpc": "2.0", "id": 1, "method": "tools/list"}]', 400),
    (b'{"jsonrpc": "2.0", "id": 1}', 400),
    (b'{"jsonrpc": "2.0", "id": {"a": 1}, "method": "tools/list"}', 400),
    (b'"just a string"', 400),
], ids=["not-json", "empty", "deep-nesting", "5000-digit-id", "invalid-utf8", "raw-nul", "batch", "no-method",
        "object-id", "string"])
def test_malformed_bodies_get_a_json_rpc_error(server, version, body, status):
    _, _, address = server
    got, _, payload = post(address, body, version=version)
    assert got == status, payload[:300]
    jsonrpc_error(payload)
    still_serving(address)


@pytest.mark.parametrize(("params", "named"), [
    ({"name": 5}, "name"),
    ({"name": "think", "arguments": [1, 2]}, "arguments"),
    ({"name": "think", "arguments": "x"}, "arguments"),
    ({"arguments": {}}, "name"),
])
def test_malformed_tool_call_params_get_a_json_rpc_error(server, params, named):
    _, _, address = server
    name = params.get("name")
    extra = f"mcp-name: {name}\r\n".encode() if isinstance(name, str) else b""
    got, _, payload = post(address, rpc("tools/call", params), method="tools/call", extra=extra)
    assert got == 400, payload[:300]
    assert named in jsonrpc_error(payload)["message"].lower(), payload[:300]
    still_serving(address)


@pytest.mark.parametrize(("head", "status", "named"), [
    (b"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1\r\nx-nul: a\x00b\r\ncontent-length: 0\r\n\r\n", 400, "header"),
    (b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + b"\x00" * 64 + b"\r\n\r\n", 400, "request line"),  # TLS
    (b"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1\r\nmcp-name: " + b"n" * 100_000 + b"\r\n\r\n", 431, "Mcp-Name"),
    (b"GET /mcp?" + b"a" * 70_000 + b" HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", 414, "request target"),
], ids=["nul-in-header", "tls-hello", "100k-header", "70k-target"])
def test_a_broken_or_oversized_http_head_gets_a_json_rpc_error(server, head, status, named):
    _, _, address = server
    got, _, payload = raw(address, head, timeout=5)
    assert got == status, payload[:300]
    assert named in jsonrpc_error(payload)["message"]
    still_serving(address)


def test_oversize_payloads_are_refused(server):
    _, url, address = server
    body = rpc("tools/call", {"name": "think", "arguments": {"thought": "x" * 1_200_000}})
    got, _, payload = post(address, body, method="tools/call", extra=b"mcp-name: think\r\n")
    assert got == 413, payload[:300]
    # chunked, no length declared: refused once it passes the limit
    head = post_head(address, None, method="tools/call", extra=b"transfer-encoding: chunked\r\nmcp-name: think\r\n")
    chunks = b"".join(b"%x\r\n%s\r\n" % (len(body[i:i + 65536]), body[i:i + 65536])
                      for i in range(0, len(body), 65536)) + b"0\r\n\r\n"
    got, _, payload = raw(address, head, chunks)
    assert got == 413, payload[:300]
    # under the body limit, over the arguments limit: a tool error naming the limit
    (_, result, _) = calls(url, [("start_episode", {}, {}), ("think", {"thought": "x" * 200_000}, None),
                                 ("finish_episode", {"reason": "token_limit"}, None)])
    assert result.is_error and "over the server's limit" in result.content[0].text
    still_serving(address)


def test_a_burst_of_1000_connections_is_served_or_refused_with_503(server):
    proc, _, (host, port) = server
    body = rpc("tools/list")
    head = post_head((host, port), len(body))
    before = memory_kb(proc.pid)
    start = time.perf_counter()
    outcomes = burst_statuses(host, port, head + body, 1000, 20)
    seconds = time.perf_counter() - start
    counts = {k: outcomes.count(k) for k in set(outcomes)}
    after = memory_kb(proc.pid)
    print(f"burst of 1000: {counts} in {seconds:.1f} s; server RSS {before['VmRSS'] // 1024} -> "
          f"{after['VmRSS'] // 1024} MB, peak {after['VmHWM'] // 1024} MB, threads {after['Threads']}")
    assert set(counts) <= {"200", "503"}, counts
    assert counts.get("200", 0) > 0
    still_serving((host, port))


@pytest.mark.parametrize("sent", ["half a request line", "headers, half the body"])
def test_a_slow_client_is_answered_408_and_closed_while_others_are_served(tight, sent):
    _, address = tight
    slow = socket.create_connection(address, timeout=TIMEOUT_S + 5)
    try:
        if sent == "half a request line":
            slow.sendall(b"POST /mc")
        else:
            slow.sendall(post_head(address, 100) + b'{"jsonrpc": "2.0", ')
        start = time.perf_counter()
        for _ in range(3):
            still_serving(address)
        data = b""
        try:
            while chunk := slow.recv(65536):
                data += chunk
        except ConnectionResetError:
            pass
        except TimeoutError:
            pytest.fail(f"the server kept a slow client ({sent}) open {time.perf_counter() - start:.1f} s "
                        f"(timeout {TIMEOUT_S} s)")
        waited = time.perf_counter() - start
    finally:
        slow.close()
    assert data.startswith(b"HTTP/1.1 408 "), data[:300]
    assert "timeout" in jsonrpc_error(data.partition(b"\r\n\r\n")[2])["message"]
    assert waited < TIMEOUT_S + 2


def test_memory_and_kept_scores_stay_bounded_under_an_episode_flood(server):
    proc, _, address = server

    def episode(i: int) -> tuple[str, bool]:
        status, _, payload = post(address, rpc("tools/call", {"name": "start_episode", "arguments": {"seed": i}}),
                                  method="tools/call", extra=b"mcp-name: start_episode\r\n")
        assert status == 200, payload[:300]
        eid = json.loads(payload)["result"]["structuredContent"]["episode_id"]
        status, _, payload = post(address, rpc("tools/call", {"name": "finish_episode", "arguments": {
            "episode_id": eid, "reason": "token_limit"}}), method="tools/call", extra=b"mcp-name: finish_episode\r\n")
        return eid, status == 200 and json.loads(payload)["result"]["structuredContent"]["done"]

    episode(0)  # the first score of the process loads the graders: not flood memory
    before = memory_kb(proc.pid)
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=8) as pool:
        done = list(pool.map(episode, range(300)))
    seconds = time.perf_counter() - start
    after = memory_kb(proc.pid)
    grown_mb = (after["VmHWM"] - before["VmHWM"]) / 1024
    print(f"episode flood of 300 (start + finish, 8 clients): {seconds:.1f} s; server RSS "
          f"{before['VmRSS'] / 1024:.0f} -> {after['VmRSS'] / 1024:.0f} MB, peak {before['VmHWM'] / 1024:.0f} -> "
          f"{after['VmHWM'] / 1024:.0f} MB")
    assert all(ok for _, ok in done)

    def result_of(eid: str) -> str:
        _, _, payload = post(address, rpc("tools/call", {"name": "episode_result", "arguments": {"episode_id": eid}}),
                             method="tools/call", extra=b"mcp-name: episode_result\r\n")
        return json.loads(payload)["result"]["content"][0]["text"]

    assert "unknown or expired" in result_of(done[0][0])  # only the newest MAX_FINISHED keep their score
    assert '"done": true' in result_of(done[-1][0])
    assert grown_mb < 64, f"the server's peak RSS grew {grown_mb:.0f} MB under the flood"


def test_legacy_sessions_are_bounded_and_refused_with_503(server):
    proc, _, address = server
    init = json.dumps({"jsonrpc": "2.0", "id": 1, "method": "initialize", "params": {
        "protocolVersion": LEGACY, "capabilities": {}, "clientInfo": {"name": "flood", "version": "0"}}}).encode()
    fds_before = open_fds(proc.pid)
    answers = [post(address, init, version=None) for _ in range(MAX_SESSIONS + 8)]
    statuses = [status for status, _, _ in answers]
    sessions = [headers["mcp-session-id"] for status, headers, _ in answers if status == 200]
    try:
        assert statuses[:MAX_SESSIONS] == [200] * MAX_SESSIONS and len(sessions) == MAX_SESSIONS, statuses
        assert statuses[MAX_SESSIONS:] == [503] * 8, statuses
        assert "Too many open sessions" in jsonrpc_error(answers[-1][2])["message"]
    finally:
        host, port = address
        for sid in sessions:  # the client's DELETE ends a session and frees its slot
            raw(address, f"DELETE /mcp HTTP/1.1\r\nHost: {host}:{port}\r\nmcp-session-id: {sid}\r\n"
                         f"mcp-protocol-version: {LEGACY}\r\nconnection: close\r\n\r\n".encode())
    assert post(address, init, version=None)[0] == 200
    assert open_fds(proc.pid) <= fds_before + 4


def test_a_request_that_finds_every_slot_taken_is_answered_503_busy(tight):
    """Both in-flight slots held by half-sent bodies: the next request waits 0.2 s and is answered 503 busy
    with Retry-After; once the holders are answered 408 the server serves again."""
    guard, address = tight
    holders = [socket.create_connection(address, timeout=5) for _ in range(2)]
    try:
        for holder in holders:
            holder.sendall(post_head(address, 100) + b'{"jsonrpc": ')
        deadline = time.monotonic() + 10
        while guard.in_flight < 2:
            assert time.monotonic() < deadline, "the half-sent requests never took their slots"
            time.sleep(0.01)
        status, headers, payload = post(address, rpc("tools/list"))
        assert status == 503 and headers.get("retry-after") == "1", payload[:300]
        assert jsonrpc_error(payload)["message"].startswith("busy:")
        assert all(holder.recv(65536).startswith(b"HTTP/1.1 408 ") for holder in holders)
    finally:
        for holder in holders:
            holder.close()
    still_serving(address)
