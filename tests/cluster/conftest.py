"""A real Ray head started with `ray start --head` on 127.0.0.1, the way cluster.yaml starts one:
token auth on, the dashboard (job-submission API) on loopback, in its own temp dir and ports so it
never touches another Ray cluster on the machine. Stopped at the end by killing exactly the
processes it started (never `ray stop`, which would stop every Ray cluster on the machine)."""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from envs._runtime import LOOPBACK_SWITCH_ENV

VENV_BIN = Path(sys.executable).parent  # not resolved: a venv's bin/python is a symlink
RAY_CLI = VENV_BIN / "ray"
REPO_ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class LocalRayHead:
    root: Path  # temp dir: Ray's session files and the token
    token: str
    gcs_port: int
    dashboard_port: int
    metrics_port: int
    session_id: int = 0  # the session of `ray start`; every daemon and worker it spawns stays in it
    env: dict[str, str] = field(default_factory=dict)

    @property
    def dashboard_url(self) -> str:
        return f"http://127.0.0.1:{self.dashboard_port}"

    def client_env(self) -> dict[str, str]:
        """What a client on the head's machine needs: token auth on and the token file."""
        return dict(self.env)

    def get(self, path: str, *, token: str | None = "own", timeout: float = 30.0) -> tuple[int, object]:
        """GET a dashboard endpoint with the head's token ("own"), another one, or none (None);
        returns (HTTP status, parsed JSON or text)."""
        sent = self.token if token == "own" else token
        headers = {} if sent is None else {"Authorization": f"Bearer {sent}"}
        request = urllib.request.Request(self.dashboard_url + path, headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=timeout) as response:
                status, body = response.status, response.read().decode("utf-8", "replace")
        except urllib.error.HTTPError as err:
            status, body = err.code, err.read().decode("utf-8", "replace")
        try:
            return status, json.loads(body)
        except ValueError:
            return status, body

    def processes(self) -> list[int]:
        """Pids of the head's processes: its session, plus descendants that left it (job drivers
        run in a new session under their job supervisor)."""
        import psutil

        members = []
        for proc in psutil.process_iter(["pid"]):
            try:
                if os.getsid(proc.pid) == self.session_id:
                    members.append(proc)
            except (ProcessLookupError, PermissionError):
                continue
        pids = set()
        for proc in members:
            pids.add(proc.pid)
            try:
                pids.update(child.pid for child in proc.children(recursive=True))
            except psutil.NoSuchProcess:
                continue
        return sorted(pids)

    def stop(self, grace_s: float = 5.0) -> None:
        import psutil

        pids = self.processes()
        for pid in pids:
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        # The GCS and raylet can outlive SIGTERM for several seconds; `ray stop` escalates too.
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and any(psutil.pid_exists(p) for p in pids):
            time.sleep(0.2)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(self.root, ignore_errors=True)


def start_local_head(num_cpus: int = 2, timeout_s: float = 90.0) -> LocalRayHead:
    # A short root: Ray's Unix sockets live under it and their paths are limited to 107 bytes.
    root = Path(tempfile.mkdtemp(prefix="hcray_", dir="/tmp"))
    token = secrets.token_hex(32)  # Ray's own generator makes the same: 256 random bits in hex
    token_file = root / "auth_token"
    token_file.write_text(token)
    token_file.chmod(0o600)
    head = LocalRayHead(root=root, token=token, gcs_port=free_port(), dashboard_port=free_port(),
                        metrics_port=free_port())
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    # The token goes by file path, not by RAY_AUTH_TOKEN, so it is not copied into every process's
    # environment dump; ~/.ray/auth_token of the machine is left alone.
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN_PATH=str(token_file), RAY_USAGE_STATS_ENABLED="0")
    # On loopback only, like a local run (envs/_runtime.py): `--node-ip-address=127.0.0.1` alone is
    # rewritten by Ray to the host's routable IP, and every server would listen on all interfaces.
    env[LOOPBACK_SWITCH_ENV] = "0"
    # Like a cluster node, the head does not have the venv on PATH (even if pytest was started from
    # an activated venv): a job's `python` is the venv's only if its runtime env says so.
    path = env.get("PATH", "").split(os.pathsep)
    env["PATH"] = os.pathsep.join(p for p in path if p and Path(p) != VENV_BIN)
    head.env = env
    command = [str(RAY_CLI), "start", "--head", "--node-ip-address=127.0.0.1", "--dashboard-host=127.0.0.1",
               f"--port={head.gcs_port}", f"--dashboard-port={head.dashboard_port}",
               # Fixed defaults (52365, 10001) would collide with another head on the machine.
               f"--dashboard-agent-listen-port={free_port()}", f"--ray-client-server-port={free_port()}",
               f"--metrics-export-port={head.metrics_port}", f"--num-cpus={num_cpus}",
               f"--temp-dir={root / 'ray'}", "--disable-usage-stats"]
    proc = subprocess.Popen(command, env=env, cwd=root, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    head.session_id = proc.pid
    try:
        output, _ = proc.communicate(timeout=timeout_s)
        if proc.returncode != 0:
            raise RuntimeError(f"`ray start --head` exited {proc.returncode}:\n{output[-4000:]}")
        deadline = time.monotonic() + timeout_s
        while True:  # the dashboard answers a little after `ray start` returns
            try:
                status, _ = head.get("/api/version", timeout=5)
                if status == 200:
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"dashboard at {head.dashboard_url} did not answer "
                                   f"within {timeout_s:.0f} s")
            time.sleep(0.5)
    except BaseException:
        proc.kill()
        head.stop()
        raise
    return head


@pytest.fixture(scope="package")
def local_ray_head():
    """One head for the package: the job tests submit to it, and test_loopback.py then reads the
    sockets of every process it has (job supervisors and workers included). Starting and stopping
    a head costs about 10 s on 2 cores."""
    head = start_local_head()
    try:
        yield head
    finally:
        head.stop()
