"""Process-wide settings the CPU path needs, applied on import of any project package, and the one
way the project starts a local Ray cluster (`init_ray`).

Two torch threads on our 2-core machines make generation 10-40x slower than one, and nothing may
reach a model hub at run time. Users should not have to remember any of this, so importing `envs`,
`actors`, `learner` or `kb_service` sets these unless the user already chose a value.

Importing the project changes no Ray security setting. Ray's own default applies: a fresh local
cluster (`ray.init()` without an address) turns token auth on and keeps its token in
`~/.ray/auth_token`; a user who wants it off says so with `RAY_AUTH_MODE=disabled`
(docs/cluster.md, "Local runs").
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
from collections.abc import Iterator
from typing import Any

CPU_RUNTIME_DEFAULTS: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "TOKENIZERS_PARALLELISM": "false",
    "RAY_USAGE_STATS_ENABLED": "0",
    "HF_HUB_OFFLINE": "1",
    "TRANSFORMERS_OFFLINE": "1",
    "HF_DATASETS_OFFLINE": "1",
    "DS_ACCELERATOR": "cpu",
}


def configure_cpu_runtime(overrides: dict[str, str] | None = None) -> dict[str, str]:
    """Set the CPU-path environment variables that are not already set.

    Returns the variables this call set. `DS_ACCELERATOR` is left alone when CUDA is visible,
    so GPU nodes keep DeepSpeed's auto-detection.
    """
    applied: dict[str, str] = {}
    for key, value in {**CPU_RUNTIME_DEFAULTS, **(overrides or {})}.items():
        if key == "DS_ACCELERATOR" and os.environ.get("CUDA_VISIBLE_DEVICES", "") not in ("", "-1"):
            continue
        if key not in os.environ:
            os.environ[key] = value
            applied[key] = value
    return applied


# What the import set (not the user): `hcgym model fetch` goes online unless the user asked for offline.
APPLIED_DEFAULTS: dict[str, str] = configure_cpu_runtime()


# --- Local Ray clusters on loopback -------------------------------------------------------------
#
# Measured with Ray 2.60 on Linux: a plain `ray.init()` binds the GCS, the raylet, every worker's
# gRPC server and the dashboard agent on all interfaces (`::`, `0.0.0.0` and the host's address),
# and `_node_ip_address="127.0.0.1"` (like `ray start --node-ip-address=127.0.0.1`) changes nothing,
# because Ray rewrites a loopback node IP to the host's routable IP
# (`ray._private.services.resolve_ip_for_localhost`). The one switch Ray reads is
# `ray_constants.ENABLE_RAY_CLUSTER` (env `RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER`): when it is off,
# `services.get_node_ip_address()` answers 127.0.0.1, the node starts with that IP, and every server
# of the node then listens on loopback only (the GCS and raylet gRPC servers listen on the node IP
# when it is 127.0.0.1). The switch is read once at `import ray`, so it is set both in the
# environment (inherited by the GCS, raylet, dashboard and, through the raylet, every worker) and
# on the already-imported module, and both are put back once the node is up, so a later
# `ray.init(address=...)` of this process joins a real cluster with its routable IP.
# tests/cluster/test_loopback.py checks every listening socket of such a cluster.

LOOPBACK_SWITCH_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
LOOPBACK_HOST = "127.0.0.1"


class RayNotOnLoopbackError(RuntimeError):
    """A local Ray cluster came up with a node IP other than loopback (a Ray upgrade changed how the
    node IP is chosen); it was shut down rather than left reachable from the network."""


def is_loopback_address(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and IPv4-mapped loopback (`::ffff:127.0.0.1`, how Ray's gRPC
    servers on a dual-stack socket report a loopback bind)."""
    try:
        address = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return host == "localhost"
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped.is_loopback
    return address.is_loopback


@contextlib.contextmanager
def _node_ip_on_loopback() -> Iterator[None]:
    """While a local node starts: make Ray pick 127.0.0.1 as this node's IP (see above)."""
    from ray._private import ray_constants

    previous_env = os.environ.get(LOOPBACK_SWITCH_ENV)
    previous_flag = ray_constants.ENABLE_RAY_CLUSTER
    os.environ[LOOPBACK_SWITCH_ENV] = "0"
    ray_constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = previous_flag
        if previous_env is None:
            os.environ.pop(LOOPBACK_SWITCH_ENV, None)
        else:
            os.environ[LOOPBACK_SWITCH_ENV] = previous_env


# --- Ray's metrics exporter in a process that starts more than one Ray session ------------------------
#
# Ray 2.60's driver exports its metrics through one OpenTelemetry MeterProvider per process (a
# singleton that is never destroyed). `ray.shutdown()` shuts that provider down, and a provider shuts
# down only once: the periodic metric reader that the next `ray.init` of the same process adds to it
# is never stopped. Each such reader keeps a thread that wakes every `metrics_report_interval_ms`,
# exports to the ended session's metrics agent (one "Failed to export metrics" line a time in that
# session's driver log) and keeps running through interpreter exit, where an export that meets C++
# static destruction can kill the process with SIGSEGV after every test passed. Measured: n sessions
# in one process leave n - 1 reader threads (tests/core/test_exit.py). So a process's second and
# later local sessions start with Ray's OpenTelemetry metrics off (the opencensus path, which Ray
# stops at shutdown); a process's first session - every production driver's only one - keeps Ray's
# default. A driver that joins a running cluster takes that cluster's setting: a cluster a test
# starts itself (`ray.cluster_utils.Cluster`) gets the same `_system_config` from
# `later_session_system_config()`.

def ray_session_ended_in_this_process() -> bool:
    """True once this process has been a Ray driver (a `ray.init` that connected) and is not one now."""
    import ray
    from ray._private import worker

    # Ray gives the global worker its GCS error subscriber when a driver connects and never removes it.
    return not ray.is_initialized() and hasattr(worker.global_worker, "gcs_error_subscriber")


def later_session_system_config() -> dict[str, Any]:
    """The `_system_config` a new Ray cluster started by this process needs (see above): Ray's
    OpenTelemetry metrics off when this process already ended a session, else nothing."""
    return {"enable_open_telemetry": False} if ray_session_ended_in_this_process() else {}


def init_ray(address: str | None = None, **options: Any) -> Any:
    """Connect to a Ray cluster, or start a fresh local one that listens on 127.0.0.1 only.

    `address` (else `RAY_ADDRESS`, as `ray job submit` sets it for its driver) joins that cluster as
    `ray.init(address=...)` does. Without one, or with `"local"`, a new single-node cluster starts on
    this machine (never one another process left running) with the GCS, raylet, workers, dashboard
    and dashboard agent on loopback. `options` are `ray.init`'s (`num_cpus`, `namespace`,
    `include_dashboard`, `runtime_env`, ...). Returns what `ray.init` returns.

    Raises ValueError for a `dashboard_host` other than loopback on a local start, and
    RayNotOnLoopbackError (after shutting the node down) if Ray still chose a routable node IP.
    """
    import ray

    address = address or os.environ.get("RAY_ADDRESS") or None
    if address and address != "local":
        return ray.init(address=address, **options)
    dashboard_host = options.pop("dashboard_host", LOOPBACK_HOST)
    if not is_loopback_address(str(dashboard_host)):
        raise ValueError(f"init_ray: dashboard_host={dashboard_host!r} would expose the local cluster's "
                         "job-submission API (code execution) to the network; local runs keep it on "
                         f"{LOOPBACK_HOST} (reach a remote head's dashboard through `ray dashboard`'s SSH tunnel)")
    system_config = {**later_session_system_config(), **(options.pop("_system_config", None) or {})}
    if system_config:
        options["_system_config"] = system_config
    with _node_ip_on_loopback():
        context = ray.init(address="local", dashboard_host=dashboard_host, **options)
    node_ip = ray.util.get_node_ip_address()
    if not is_loopback_address(node_ip):
        ray.shutdown()
        raise RayNotOnLoopbackError(f"init_ray: the local Ray node started with IP {node_ip}, not loopback, so its "
                                    "servers would listen on the network; it was shut down (Ray "
                                    f"{ray.__version__} no longer honours {LOOPBACK_SWITCH_ENV}=0)")
    return context
