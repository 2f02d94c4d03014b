"""Checkpoint primitives: safetensors weights, weights-only torch state, RNG states, atomic JSON.

Loading never unpickles arbitrary objects: tensors come from safetensors, optimizer states through
`torch.load(weights_only=True)` (tensors and plain containers only), everything else from JSON.

Layout of a run's checkpoints (the driver owns the directory; each actor writes its part):

    RUN_DIR/checkpoints/step_000004/
        learner/            policy/ (HF checkpoint: sharded safetensors + index, config, tokenizer),
                            optimizer*.pt, rng*.json, learner_state.json
        teacher/            teacher.safetensors, teacher_state.json
        driver.json         data position, step, ... (written by the driver)
    RUN_DIR/checkpoints/latest   -> "step_000004" (written last, so a crash mid-save leaves the old one)
"""

from __future__ import annotations

import json
import os
import random
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load_file, save_file

LATEST = "latest"


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON through a temporary file and rename, so readers never see half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "w") as handle:
        json.dump(obj, handle, indent=1, sort_keys=True)
    os.replace(tmp, path)


def read_json(path: str | os.PathLike) -> Any:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint file missing: {path}")
    with open(path) as handle:
        return json.load(handle)


def save_tensors(path: str | os.PathLike, tensors: dict[str, torch.Tensor], metadata: dict[str, str] | None = None) -> None:
    """Save a flat name -> tensor dict with safetensors (contiguous CPU copies, atomic rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    clean = {k: v.detach().to("cpu").contiguous() for k, v in tensors.items()}
    tmp = path.with_name(f".{path.name}.tmp")
    save_file(clean, str(tmp), metadata=metadata)
    os.replace(tmp, path)


def load_tensors(path: str | os.PathLike, device: str = "cpu") -> dict[str, torch.Tensor]:
    """Load a safetensors file (no pickle involved)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint tensor file missing: {path}")
    return load_file(str(path), device=device)


def save_torch_state(path: str | os.PathLike, obj: Any) -> None:
    """torch.save for optimizer states: only tensors and plain containers, so `load_torch_state` can read it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load_torch_state(path: str | os.PathLike) -> Any:
    """torch.load with `weights_only=True`: refuses anything but tensors and primitive containers."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint state file missing: {path}")
    return torch.load(path, map_location="cpu", weights_only=True)


# ----------------------------------------------------------------------------------------------
# RNG states
# ----------------------------------------------------------------------------------------------


def capture_rng_state() -> dict[str, Any]:
    """Python, NumPy, torch CPU (and CUDA when present) RNG states as JSON-ready data."""
    version, internal, gauss = random.getstate()
    np_state = np.random.get_state()
    state: dict[str, Any] = {
        "python": [version, list(internal), gauss],
        "numpy": [np_state[0], np_state[1].tolist(), int(np_state[2]), int(np_state[3]), float(np_state[4])],
        "torch": torch.get_rng_state().tolist(),
    }
    if torch.cuda.is_available():
        state["cuda"] = [s.tolist() for s in torch.cuda.get_rng_state_all()]
    return state


def restore_rng_state(state: dict[str, Any]) -> None:
    """Inverse of `capture_rng_state`."""
    for key in ("python", "numpy", "torch"):
        if key not in state:
            raise ValueError(f"RNG state lacks the {key!r} entry")
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))
    name, keys, pos, has_gauss, cached = state["numpy"]
    np.random.set_state((name, np.array(keys, dtype=np.uint32), pos, has_gauss, cached))
    torch.set_rng_state(torch.tensor(state["torch"], dtype=torch.uint8))
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([torch.tensor(s, dtype=torch.uint8) for s in state["cuda"]])


# ----------------------------------------------------------------------------------------------
# Directory layout
# ----------------------------------------------------------------------------------------------


def checkpoint_dir(run_dir: str | os.PathLike, step: int) -> Path:
    """RUN_DIR/checkpoints/step_000123."""
    return Path(run_dir) / "checkpoints" / f"step_{step:06d}"


def mark_latest(run_dir: str | os.PathLike, step: int) -> None:
    """Point `latest` at a finished checkpoint (call after every part is written)."""
    target = checkpoint_dir(run_dir, step)
    if not target.is_dir():
        raise FileNotFoundError(f"cannot mark missing checkpoint {target} as latest")
    latest = Path(run_dir) / "checkpoints" / LATEST
    tmp = latest.with_name(f".{LATEST}.tmp")
    tmp.write_text(target.name)
    os.replace(tmp, latest)


def latest_checkpoint(run_dir: str | os.PathLike) -> Path | None:
    """The directory `latest` points to, or None when the run has no finished checkpoint."""
    latest = Path(run_dir) / "checkpoints" / LATEST
    if not latest.exists():
        return None
    target = latest.parent / latest.read_text().strip()
    if not target.is_dir():
        raise FileNotFoundError(f"{latest} points to {target.name}, which does not exist")
    return target


def prune_checkpoints(run_dir: str | os.PathLike, keep_last: int) -> list[Path]:
    """Delete all but the newest `keep_last` step directories (never the one `latest` names)."""
    if keep_last < 1:
        raise ValueError(f"keep_last must be >= 1, got {keep_last}")
    root = Path(run_dir) / "checkpoints"
    if not root.is_dir():
        return []
    steps = sorted(p for p in root.iterdir() if p.is_dir() and p.name.startswith("step_"))
    latest = latest_checkpoint(run_dir)
    removed = []
    for path in steps[:-keep_last]:
        if latest is not None and path.resolve() == latest.resolve():
            continue
        shutil.rmtree(path)
        removed.append(path)
    return removed
