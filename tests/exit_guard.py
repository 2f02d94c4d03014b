"""How the test process ends: a crash while the interpreter shuts down prints every thread's stack,
and what the tests started is stopped before Python starts tearing itself down.

Loaded by tests/conftest.py (and, alone, by tests/core/test_exit.py's throwaway pytest runs).

Why it matters: pytest's own faulthandler plugin turns the handler off in `pytest_unconfigure` and
turns it back on only when it was on before pytest started (`PYTHONFAULTHANDLER=1`, `-X
faulthandler`). A SIGSEGV after the last test (module teardown, C++ static destructors, a thread
waking up during finalization) then kills the process with no stack at all: `make test` printed
"N passed" and make reported "Segmentation fault". The handler is put back here, after pytest's.

Python threads still alive when the interpreter finalizes are the common cause of such a crash on
CPython 3.11: a daemon thread that wakes up (a socket closed by the main thread's teardown, a
timed wait) while Py_FinalizeEx frees the thread states can take the GIL with a dangling thread
state (cpython#110052). So the session ends by stopping Ray if a test left it running and by
naming any non-main Python thread that is still alive; `tests/exit_check.py` runs the teardown-heavy
part of the suite in fresh processes and fails on any non-zero exit.
"""

from __future__ import annotations

import faulthandler
import gc
import os
import sys
import threading
import traceback

import pytest

# Threads of third-party libraries that are stopped and joined by their own atexit handler, which
# runs before the interpreter finalizes (tqdm's monitor: `atexit.register(TMonitor.exit)`).
JOINED_AT_EXIT = ("tqdm_monitor",)


def _native_ids() -> set[int]:
    try:
        return {int(tid) for tid in os.listdir("/proc/self/task")}
    except OSError:  # not Linux: every registered thread counts
        return {t.native_id for t in threading.enumerate() if t.native_id is not None}


def leftover_threads() -> list[threading.Thread]:
    """Python threads other than the calling one that are still running (and not joined at exit by
    their owner's atexit handler). A native thread that once called into Python (gloo, Ray's core
    worker) stays registered as a `_DummyThread` after it ended; it counts only while it runs."""
    me = threading.current_thread()
    running = _native_ids()
    return [t for t in threading.enumerate()
            if t is not me and t.is_alive() and t.name not in JOINED_AT_EXIT and not t.name.startswith("pydevd")
            and not (isinstance(t, threading._DummyThread) and t.native_id not in running)]


def describe(threads: list[threading.Thread]) -> str:
    frames = sys._current_frames()
    lines = []
    for t in threads:
        frame = frames.get(t.ident)
        where = traceback.format_stack(frame, limit=4) if frame is not None else ["  (no Python frame)\n"]
        lines.append(f"thread {t.name!r} (daemon={t.daemon}, native id {t.native_id}):\n{''.join(where)}")
    return "".join(lines)


def release_stopped_ray_nodes() -> int:
    """Drop the GCS clients of Ray nodes this process started and stopped; returns how many.

    Ray pins every node it starts in-process (each `ray.cluster_utils.Cluster` node, a local
    `ray.init`'s head) in an atexit closure until the process exits, and with it the node's GCS
    client, whose gRPC polling thread (`client.poll0`) keeps running against the dead GCS. Measured:
    5 such threads after tests/training/test_placement.py's simulated cluster was shut down; they were
    torn down only during interpreter finalization. Dropping the client stops its thread now (the
    atexit handler only kills the node's processes, it does not use the client)."""
    import ray
    from ray._private.node import Node

    if ray.is_initialized():
        return 0
    released = 0
    for obj in gc.get_objects():
        if isinstance(obj, Node) and getattr(obj, "_gcs_client", None) is not None:
            obj._gcs_client = None
            released += 1
    gc.collect()
    return released


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session) -> None:
    """After every fixture's teardown: stop a Ray driver a test left connected (its own atexit
    handler would do it later, during interpreter exit), then report Python threads still alive."""
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
    if ray is not None:
        release_stopped_ray_nodes()
    # Objects the tests dropped inside reference cycles (weight-sync groups with their gloo process
    # group and TCPStore server thread, asyncio loops) are destroyed now, while the interpreter is
    # whole, not by the last collection of interpreter shutdown, after the thread states are gone
    # (weight-sync groups and their running `pt_tcpstore_uv` server thread outlive the last test of
    # tests/training otherwise).
    gc.collect()
    threads = leftover_threads()
    for thread in threads:
        # A thread started outside Python (torch, gloo) shows as a _DummyThread, which cannot be joined.
        if not isinstance(thread, threading._DummyThread):
            thread.join(timeout=5.0)
    threads = [t for t in threads if t.is_alive()]
    if threads:
        message = (f"{len(threads)} Python thread(s) still running at the end of the session; a thread that "
                   f"outlives the tests can crash the interpreter's exit:\n{describe(threads)}")
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_sep("=", "threads left running", yellow=True)
            reporter.write_line(message)
        else:
            sys.stderr.write(message + "\n")


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Runs after pytest's faulthandler plugin has switched the handler off: switch it back on, for
    every thread, on the process's stderr, so a crash during interpreter exit prints its stacks."""
    if not faulthandler.is_enabled():
        faulthandler.enable(file=sys.__stderr__ if sys.__stderr__ is not None else os.fdopen(2, "w"),
                            all_threads=True)
