"""How a test process ends: a crash during interpreter exit prints every thread's stack."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]

# A throwaway test module whose process crashes (SIGSEGV) in an atexit handler, i.e. after pytest has
# finished and unconfigured, while a second thread is parked in a function with a recognisable name.
CRASHING_TEST = '''
import atexit, faulthandler, threading, time

def parked_thread_of_the_crashing_process():
    while True:
        time.sleep(0.05)

def crash_at_exit():
    started = threading.Event()
    threading.Thread(target=lambda: (started.set(), parked_thread_of_the_crashing_process()),
                     name="parked", daemon=True).start()
    started.wait(10)
    faulthandler._sigsegv()

def test_registers_a_crash_at_exit():
    atexit.register(crash_at_exit)
'''


def _run_crashing_pytest(tmp_path: Path, *plugins: str) -> subprocess.CompletedProcess:
    (tmp_path / "test_crash.py").write_text(CRASHING_TEST)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONFAULTHANDLER"}
    env["PYTHONPATH"] = str(REPO_ROOT)
    args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path)]
    for plugin in plugins:
        args += ["-p", plugin]
    return subprocess.run([*args, "test_crash.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)


def test_a_crash_after_pytest_finished_prints_every_threads_stack(tmp_path):
    # pytest alone switches faulthandler off at unconfigure: the process dies silently.
    bare = _run_crashing_pytest(tmp_path)
    assert bare.returncode == -11, (bare.returncode, bare.stderr[-2000:])
    assert "1 passed" in bare.stdout and "Fatal Python error" not in bare.stderr

    # With the suite's exit guard the same crash names itself and shows both threads' stacks.
    guarded = _run_crashing_pytest(tmp_path, "tests.exit_guard")
    assert guarded.returncode == -11, (guarded.returncode, guarded.stderr[-2000:])
    assert "Fatal Python error: Segmentation fault" in guarded.stderr, guarded.stderr[-2000:]
    assert "in crash_at_exit" in guarded.stderr                          # the crashing (main) thread
    assert "in parked_thread_of_the_crashing_process" in guarded.stderr  # every other thread too


# A throwaway test that starts and stops a simulated two-node Ray cluster, as
# tests/training/test_placement.py does, and records at exit how many gRPC polling threads of Ray
# clients are still running (atexit handlers run while the interpreter is still whole).
CLUSTER_TEST = '''
import atexit, os, sys

def _running(name):
    count = 0
    for tid in os.listdir("/proc/self/task"):
        try:
            count += open(f"/proc/self/task/{tid}/comm").read().strip() == name
        except OSError:  # the thread ended while we looked
            pass
    return count

def test_a_simulated_cluster_comes_and_goes():
    import ray
    from ray.cluster_utils import Cluster

    sim = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    sim.add_node(num_cpus=1)
    ray.init(address=sim.address, log_to_driver=False)
    assert ray.get(ray.put(7)) == 7
    ray.shutdown()
    sim.shutdown()
    out = sys.argv[-1].replace("test_cluster.py", "threads_at_exit.txt")
    atexit.register(lambda: open(out, "w").write(str(_running("client.poll0"))))

def test_a_second_session_leaves_no_metric_exporter_running():
    """Runs after the simulated cluster: this process's second Ray session."""
    import glob, time
    import ray
    from envs._runtime import init_ray, later_session_system_config

    assert later_session_system_config() == {"enable_open_telemetry": False}
    init_ray("local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    assert ray.get(ray.put(8)) == 8
    logs = ray._private.worker._global_node.get_logs_dir_path()
    ray.shutdown()
    time.sleep(1.5)  # past an export interval (1 s here) of a reader left running
    lines = 0
    for path in glob.glob(f"{logs}/python-core-driver-*.log"):
        lines += sum("open_telemetry_metric_recorder" in line and "Failed to export" in line for line in open(path))
    out = sys.argv[-1].replace("test_cluster.py", "exports_after_shutdown.txt")
    open(out, "w").write(str(lines))
'''


def test_stopped_ray_sessions_leave_no_grpc_client_or_metric_exporter_running_into_exit(tmp_path):
    (tmp_path / "test_cluster.py").write_text(CLUSTER_TEST)
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), "PYTHONFAULTHANDLER": "1", "RAY_USAGE_STATS_ENABLED": "0",
           "RAY_metrics_report_interval_ms": "1000"}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path),
                           "-p", "tests.exit_guard", str(tmp_path / "test_cluster.py")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-3000:], proc.stderr[-3000:])
    # Ray keeps every node it started in-process (and the node's GCS client with its gRPC polling
    # thread) alive until interpreter exit; the guard releases them at the end of the session.
    assert (tmp_path / "threads_at_exit.txt").read_text() == "0"
    # Ray's OpenTelemetry metric reader of a process's second session is never stopped (its meter
    # provider was shut down with the first session): it would export every interval to the dead
    # session's agent and on through interpreter exit. That session starts with those metrics off.
    assert (tmp_path / "exports_after_shutdown.txt").read_text() == "0"
