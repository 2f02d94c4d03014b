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
import math
import os
import random
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load_file, save_file

from envs.core.files import as_disk_full, replace_atomic

LATEST = "latest"
STEP_DIR_PATTERN = re.compile(r"step_\d{6,}")


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, malformed or points outside its run; the message names the file."""


def find_non_finite(obj: Any, path: str = "") -> str | None:
    """The key path (`history[3].kl`) of the first NaN or infinity in a JSON-ready value, or None."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return path or "<top level>"
    if isinstance(obj, dict):
        for key, value in obj.items():
            found = find_non_finite(value, f"{path}.{key}" if path else str(key))
            if found:
                return found
    elif isinstance(obj, (list, tuple)):
        for index, value in enumerate(obj):
            found = find_non_finite(value, f"{path}[{index}]")
            if found:
                return found
    return None


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON through a temporary file and rename, so readers never see half a file.

    NaN and infinity are refused (strict JSON has no spelling for them; Python would write the bare
    token `NaN`, which other readers reject, and a checkpoint must reload to the values it saved).
    On any failure the temporary file is removed and the previous file, if any, is left as it was.

    Raises:
        CheckpointError: naming the file and the key path of the first non-finite number.
        TypeError: naming the file, for a value JSON cannot represent.
        DiskFullError: naming the file, when the disk is full.
    """
    path = Path(path)
    bad = find_non_finite(obj)
    if bad is not None:
        raise CheckpointError(f"{path}: refusing to write a non-finite number (NaN or infinity) at key {bad!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            json.dump(obj, handle, indent=1, sort_keys=True, allow_nan=False)
        os.replace(tmp, path)
    except BaseException as exc:
        full = as_disk_full(exc, path)  # before the unlink gives the space back
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, TypeError):
            raise TypeError(f"{path}: {exc}") from exc
        if full is not None and full is not exc:
            raise full from exc
        raise


def read_json(path: str | os.PathLike, required: dict[str, type | tuple[type, ...]] | None = None) -> Any:
    """A JSON checkpoint file; every failure names the file.

    Args:
        path: The file.
        required: Keys the top-level object must have, with their types (`bool` never counts as `int`).

    Raises:
        FileNotFoundError: the file is missing.
        CheckpointError: unreadable, not UTF-8, truncated or invalid JSON, or a required key missing
            or of the wrong type.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint file missing: {path}")
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot read the checkpoint file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise CheckpointError(f"{path}: checkpoint file is not UTF-8 text (bad byte at offset {exc.start})") from None
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        # A save cut short ends mid-value: the parser stops at the end or inside an open string.
        cut_short = exc.pos >= len(text.rstrip()) or exc.msg.startswith("Unterminated string")
        hint = " (truncated?)" if cut_short else ""
        raise CheckpointError(f"{path}: not valid JSON{hint} at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except (RecursionError, ValueError) as exc:
        raise CheckpointError(f"{path}: checkpoint file cannot be parsed ({type(exc).__name__})") from None
    for key, kind in (required or {}).items():
        if not isinstance(obj, dict):
            raise CheckpointError(f"{path}: expected a JSON object with key {key!r}, got a JSON {type(obj).__name__}")
        if key not in obj:
            raise CheckpointError(f"{path}: missing key {key!r}")
        value = obj[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " or ".join(k.__name__ for k in kinds)
            raise CheckpointError(f"{path}: key {key!r} should be {names}, got {type(value).__name__} {value!r:.60}")
    return obj


def save_tensors(path: str | os.PathLike, tensors: dict[str, torch.Tensor], metadata: dict[str, str] | None = None) -> None:
    """Save a flat name -> tensor dict with safetensors (contiguous CPU copies, atomic rename)."""
    path = Path(path)
    clean = {k: v.detach().to("cpu").contiguous() for k, v in tensors.items()}
    replace_atomic(path, lambda tmp: save_file(clean, str(tmp), metadata=metadata))


def load_tensors(path: str | os.PathLike, device: str = "cpu") -> dict[str, torch.Tensor]:
    """Load a safetensors file (no pickle involved).

    Raises:
        FileNotFoundError: the file is missing.
        CheckpointError: naming the file, when it is not a valid safetensors file (truncated, corrupt).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint tensor file missing: {path}")
    try:
        return load_file(str(path), device=device)
    except Exception as exc:  # safetensors raises SafetensorError / OSError with no file name
        raise CheckpointError(f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})") from None


def save_torch_state(path: str | os.PathLike, obj: Any) -> None:
    """torch.save for optimizer states: only tensors and plain containers, so `load_torch_state` can read it."""
    replace_atomic(Path(path), lambda tmp: torch.save(obj, tmp))


def load_torch_state(path: str | os.PathLike) -> Any:
    """torch.load with `weights_only=True`: refuses anything but tensors and primitive containers.

    Raises:
        FileNotFoundError: the file is missing.
        CheckpointError: naming the file, when it is corrupt or holds objects weights-only loading refuses.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint state file missing: {path}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # pickle.UnpicklingError, RuntimeError (bad zip), EOFError ...
        raise CheckpointError(f"{path}: not a loadable weights-only torch state ({type(exc).__name__}: {exc})") from None


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


def restore_rng_state(state: dict[str, Any], source: str | os.PathLike | None = None) -> None:
    """Inverse of `capture_rng_state`.

    Args:
        state: What `capture_rng_state` returned (read back from JSON).
        source: The file it came from, named in errors.

    Raises:
        ValueError: an entry is missing or malformed (a `CheckpointError` naming `source` when given).
    """
    where = f"{source}: " if source is not None else ""
    error = CheckpointError if source is not None else ValueError
    if not isinstance(state, dict):
        raise error(f"{where}RNG state should be a JSON object, got {type(state).__name__}")
    for key in ("python", "numpy", "torch"):
        if key not in state:
            raise error(f"{where}RNG state lacks the {key!r} entry")
    entry = "python"
    try:
        version, internal, gauss = state["python"]
        python_state = (version, tuple(internal), gauss)
        random.Random().setstate(python_state)  # trial on a scratch generator: raises on a bad state
        entry = "numpy"
        name, keys, pos, has_gauss, cached = state["numpy"]
        numpy_state = (name, np.array(keys, dtype=np.uint32), pos, has_gauss, cached)
        np.random.RandomState().set_state(numpy_state)
        entry = "torch"
        torch_state = torch.tensor(state["torch"], dtype=torch.uint8)
        torch.Generator().set_state(torch_state)
        entry = "cuda"
        cuda_states = [torch.tensor(s, dtype=torch.uint8) for s in state.get("cuda", [])]
    except (TypeError, ValueError, IndexError, KeyError, OverflowError, RuntimeError) as exc:
        raise error(f"{where}RNG state entry {entry!r} is malformed ({type(exc).__name__}: {exc})") from None
    # Every entry parsed and was accepted by a scratch generator: only now touch the global ones,
    # so a bad file leaves them as they were.
    random.setstate(python_state)
    np.random.set_state(numpy_state)
    torch.set_rng_state(torch_state)
    if cuda_states and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(cuda_states)


# ----------------------------------------------------------------------------------------------
# Directory layout
# ----------------------------------------------------------------------------------------------


def checkpoint_dir(run_dir: str | os.PathLike, step: int) -> Path:
    """RUN_DIR/checkpoints/step_000123."""
    return Path(run_dir) / "checkpoints" / f"step_{step:06d}"


def mark_latest(run_dir: str | os.PathLike, step: int) -> None:
    """Point `latest` at a finished checkpoint (call after every part is written).

    Temporary files of atomic writes (`.NAME.tmp`, `.NAME.XXXXXXXX.tmp`) still in the folder were
    left by a writer killed before its rename; they are not part of the checkpoint and are removed
    first, so a finished checkpoint never holds one."""
    target = checkpoint_dir(run_dir, step)
    if not target.is_dir():
        raise FileNotFoundError(f"cannot mark missing checkpoint {target} as latest")
    for leftover in temp_files(target):
        leftover.unlink(missing_ok=True)
    latest = Path(run_dir) / "checkpoints" / LATEST
    replace_atomic(latest, lambda tmp: tmp.write_text(target.name, encoding="utf-8"))


def temp_files(directory: str | os.PathLike) -> list[Path]:
    """Temporary files of interrupted atomic writes under `directory` (see `write_json_atomic` and
    envs.core.files.replace_atomic: a dot, the file's name, `.tmp`)."""
    return sorted(p for p in Path(directory).rglob(".*.tmp") if p.is_file())


def latest_checkpoint(run_dir: str | os.PathLike) -> Path | None:
    """The directory `latest` points to, or None when the run has no finished checkpoint.

    `latest` holds one folder name, `step_NNNNNN`, of the run's own checkpoints folder; anything
    else (a path, `..`, a symlink leading elsewhere) is refused, so a crafted or damaged run folder
    cannot make a resume read files from outside it.

    Raises:
        CheckpointError: naming the `latest` file when it is unreadable or points anywhere else.
        FileNotFoundError: the step folder it names does not exist.
    """
    root = Path(run_dir) / "checkpoints"
    latest = root / LATEST
    if not latest.exists():
        return None
    try:
        name = latest.read_bytes().decode("utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{latest}: unreadable ({type(exc).__name__}); expected a folder name like "
                              f"step_000004") from None
    if not STEP_DIR_PATTERN.fullmatch(name):
        raise CheckpointError(f"{latest}: points to {name[:200]!r}, not a step folder of {root} "
                              f"(expected a name like step_000004)")
    target = root / name
    if not target.is_dir():
        raise FileNotFoundError(f"{latest} points to {target.name}, which does not exist")
    if target.resolve().parent != root.resolve():
        raise CheckpointError(f"{latest}: {name} resolves to {target.resolve()}, outside {root}")
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
