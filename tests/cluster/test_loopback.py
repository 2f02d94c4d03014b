"""A local run listens on loopback only, and importing the project changes no Ray auth setting.

The run is started in a child process exactly as the project starts one (`envs._runtime.init_ray`,
then the KB service and an env-actor pool with a runtime env, plus the dashboard), so every process
of that cluster is a descendant of the child; each one's listening sockets are read with psutil
(`ss -ltnp` when psutil may not read them) and must all be on 127.0.0.0/8, ::1 or ::ffff:127.x.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from envs._runtime import LOOPBACK_SWITCH_ENV, init_ray, is_loopback_address

psutil = pytest.importorskip("psutil")
pytestmark = pytest.mark.ray

REPO_ROOT = Path(__file__).resolve().parents[2]

# The child: a local run (KB service replicas, env actors with a runtime env, the dashboard), then
# it waits until the test closes its stdin.
LOCAL_RUN = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    from envs._runtime import init_ray
    import ray
    from tests.kb.conftest import make_corpus, write_jsonl
    from kb_service.ingest import build_kb, file_input
    from kb_service.service import start_kb_service
    from actors.env_actor import EnvPool

    root = Path(sys.argv[1])
    build_kb([file_input(write_jsonl(root / "passages.jsonl", make_corpus(n_filler=30)))], root / "kb",
             progress=False, echo=lambda s: None)
    context = init_ray(num_cpus=2, include_dashboard=True, log_to_driver=False, namespace="hcgym-loopback-test")
    kb = start_kb_service(replicas=1, path=root / "kb", name="loopback-kb", num_cpus=0.25)
    pool = EnvPool(num_actors=1, slots_per_actor=1, max_turns=4, num_cpus=0.25, kb_service="loopback-kb",
                   domain_modules={"ward": "tests.fixtures.ward_domain.environment"},
                   env_vars={"HCGYM_EMBEDDINGS": "0"})
    ray.get([a.ping.remote() for a in pool.actors], timeout=180)
    assert kb.search("asthma corticosteroid", k=3)
    print("READY " + json.dumps({"node_ip": ray.util.get_node_ip_address(),
                                 "dashboard_port": int(context.dashboard_url.rsplit(":", 1)[1])}), flush=True)
    sys.stdin.read()
    ray.shutdown()
""")


def _listening_sockets_psutil(processes: list) -> list[tuple[str, str, int]]:
    found = []
    for proc in processes:
        try:
            for conn in proc.net_connections(kind="inet"):
                if conn.status == psutil.CONN_LISTEN:
                    found.append((proc.name(), conn.laddr.ip, conn.laddr.port))
        except psutil.NoSuchProcess:
            continue
    return found


def _listening_sockets_ss(pids: set[int]) -> list[tuple[str, str, int]]:
    """`ss -ltnp` rows of these pids: `LISTEN 0 128 [::ffff:127.0.0.1]:4242 ... users:(("raylet",pid=7,fd=9))`."""
    text = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, check=True).stdout
    found = []
    for line in text.splitlines():
        fields = line.split()
        owners = re.findall(r'\("([^"]+)",pid=(\d+)', line)
        local = fields[3]
        host, port = local.rsplit(":", 1)
        for name, pid in owners:
            if int(pid) in pids:
                found.append((name, host.strip("[]"), int(port)))
    return found


def listening_sockets(root_pid: int) -> list[tuple[str, str, int]]:
    """(process name, address, port) of every listening TCP socket of `root_pid` and its descendants."""
    root = psutil.Process(root_pid)
    processes = [root, *root.children(recursive=True)]
    try:
        return _listening_sockets_psutil(processes)
    except psutil.AccessDenied:
        return _listening_sockets_ss({p.pid for p in processes})


def listening_sockets_of_one(pid: int) -> list[tuple[str, str, int]]:
    try:
        return _listening_sockets_psutil([psutil.Process(pid)])
    except psutil.AccessDenied:
        return _listening_sockets_ss({pid})


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.1.1", "::1", "::ffff:127.0.0.1", "localhost"])
def test_loopback_addresses_are_recognised(host):
    assert is_loopback_address(host)


@pytest.mark.parametrize("host", ["0.0.0.0", "::", "192.0.2.2", "10.0.0.5", "::ffff:10.0.0.5", "fe80::1%eth0", ""])
def test_other_addresses_are_not_loopback(host):
    assert not is_loopback_address(host)


def test_a_local_dashboard_on_a_public_host_is_refused_before_anything_starts():
    import ray

    was_initialized = ray.is_initialized()
    with pytest.raises(ValueError, match="dashboard_host='0.0.0.0'.*network"):
        init_ray(address="local", num_cpus=1, dashboard_host="0.0.0.0")
    assert ray.is_initialized() == was_initialized
    assert os.environ.get(LOOPBACK_SWITCH_ENV) != "0"


@pytest.mark.slow
def test_every_socket_of_a_local_run_listens_on_loopback(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("RAY_ADDRESS", LOOPBACK_SWITCH_ENV)}
    env["PYTHONPATH"] = str(REPO_ROOT)
    child = subprocess.Popen([sys.executable, "-c", LOCAL_RUN, str(tmp_path)], cwd=REPO_ROOT, env=env,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = ""
        for line in child.stdout:
            if line.startswith("READY"):
                ready = line
                break
        assert ready, f"the local run did not start: {child.stderr.read()[-3000:] if child.poll() is not None else ''}"
        started = json.loads(ready.split(" ", 1)[1])
        assert started["node_ip"] == "127.0.0.1", ready
        sockets = listening_sockets(child.pid)
        names = {name for name, _, _ in sockets}
        # The cluster's servers were found (a discovery that sees nothing would pass vacuously).
        assert {"gcs_server", "raylet"} <= names, sockets
        assert any("KBActor" in n for n in names) and any("EnvActor" in n for n in names), sockets
        assert started["dashboard_port"] in {port for _, _, port in sockets}, sockets
        exposed = [s for s in sockets if not is_loopback_address(s[1])]
        assert exposed == [], f"listening on a non-loopback address: {exposed}"
    finally:
        if child.poll() is None:
            child.stdin.close()
            try:
                child.wait(timeout=60)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()


def test_importing_the_project_sets_no_ray_auth_mode():
    env = {k: v for k, v in os.environ.items() if k != "RAY_AUTH_MODE"}
    env["PYTHONPATH"] = str(REPO_ROOT)
    code = ("import os, envs, actors, learner, kb_service, evals; "
            f"print(repr(os.environ.get('RAY_AUTH_MODE')), repr(os.environ.get('{LOOPBACK_SWITCH_ENV}')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                         check=True, timeout=300).stdout.strip().splitlines()[-1]
    assert out == "None None"


@pytest.mark.slow
def test_every_socket_of_a_local_ray_start_head_listens_on_loopback(local_ray_head):
    """The `ray start --head` path (tests/cluster's head, a user's local head) with the same switch."""
    sockets = []
    for pid in local_ray_head.processes():
        try:
            sockets += listening_sockets_of_one(pid)
        except psutil.NoSuchProcess:
            continue
    names = {name for name, _, _ in sockets}
    assert {"gcs_server", "raylet"} <= names, sockets
    assert local_ray_head.dashboard_port in {port for _, _, port in sockets}, sockets
    exposed = [s for s in sockets if not is_loopback_address(s[1])]
    assert exposed == [], f"listening on a non-loopback address: {exposed}"
