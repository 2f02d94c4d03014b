"""Process-wide settings the CPU path needs, applied on import of any project package.

Two torch threads on our 2-core machines make generation 10-40x slower than one; Ray 2.60
turns token auth on by default, which breaks local `ray job submit`; and nothing may reach a
model hub at run time. Users should not have to remember any of this, so importing `envs`,
`actors`, `learner` or `kb_service` sets these unless the user already chose a value.
"""

from __future__ import annotations

import os

CPU_RUNTIME_DEFAULTS: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "TOKENIZERS_PARALLELISM": "false",
    "RAY_AUTH_MODE": "disabled",
    "RAY_USAGE_STATS_ENABLED": "0",
    "HF_HUB_OFFLINE": "1",
    "TRANSFORMERS_OFFLINE": "1",
    "HF_DATASETS_OFFLINE": "1",
    "DS_ACCELERATOR": "cpu",
}


def _has_nvidia_device() -> bool:
    if os.environ.get("CUDA_VISIBLE_DEVICES", None) in ("", "-1"):
        return False
    return os.path.exists("/dev/nvidia0") or os.path.exists("/proc/driver/nvidia/version")


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
