"""Figures shared by the GPU benches: a learner step's FLOPs, the device's dense bf16 peak, MFU, the
vLLM interpreter, and a JSON file of figures that grows phase by phase.

FLOPs of one learner step (matmul FLOPs; attention scores, recomputation under gradient
checkpointing and the embedding lookup left out, as in the usual 6N rule):

    passes * (N - N_head) * tokens + passes * N_head * loss_tokens

* passes = 6 (policy forward + backward) + 2 (the frozen reference's forward, when kl_beta > 0).
* N: the model's parameters (a tied embedding/head matrix counted once), N_head = vocab * hidden:
  the LM head runs only on the loss positions in our learner (learner/backends/worker.py passes
  `positions=loss_mask` to `modeling.model.token_stats`, which gathers those hidden states before
  the head), so its FLOPs scale with the loss tokens, not with every position.
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict

ROOT = Path(__file__).resolve().parents[1]

# Dense bf16 Tensor Core peaks, TFLOPS. NVIDIA's datasheets print them "with sparsity" (2x dense);
# the figures below are half of those:
#   H100 SXM 1,979* / H100 PCIe 1,513*: NVIDIA H100 Tensor Core GPU datasheet (specifications table,
#     "* Shown with sparsity. Specifications 1/2 lower without sparsity"),
#     https://www.nvidia.com/en-us/data-center/h100/ ; H100 NVL 1,671* on the same page.
#   H200 SXM 1,979* / H200 NVL 1,671*: https://www.nvidia.com/en-us/data-center/h200/
#   A100 (SXM4 and PCIe, 40 GB and 80 GB) 312 dense (624*): NVIDIA A100 datasheet,
#     https://www.nvidia.com/en-us/data-center/a100/
# Patterns run on torch.cuda.get_device_name() upper-cased, first match wins (NVL before the plain
# name). "NVIDIA H100 80GB HBM3" is the SXM part (the PCIe card is HBM2e and says "PCIe"); a bare
# "NVIDIA H100" or any other name matches nothing: no MFU rather than a wrong peak.
PEAK_BF16_DENSE_TFLOPS: list[tuple[str, str, float]] = [
    (r"\bH100\b.*\bNVL\b", "H100 NVL", 1671 / 2),
    (r"\bH100\b.*\bPCIE\b", "H100 PCIe", 1513 / 2),
    (r"\bH100\b.*(\bSXM|\bHBM3\b)", "H100 SXM", 1979 / 2),
    (r"\bH200\b.*\bNVL\b", "H200 NVL", 1671 / 2),
    (r"\bH200\b", "H200 SXM", 1979 / 2),
    (r"\bA100\b", "A100", 312.0),
]


class Peak(BaseModel):
    model_config = ConfigDict(extra="forbid")
    device: str
    model: str | None = None      # the datasheet model the name matched
    tflops: float | None = None   # dense bf16; None when unknown
    reason: str


def device_peak(device_name: str, override_tflops: float | None = None) -> Peak:
    """The dense bf16 peak of a device from its name (or `override_tflops`), or None with the reason."""
    if override_tflops is not None:
        if override_tflops <= 0:
            raise ValueError(f"--peak-tflops must be > 0, got {override_tflops}")
        return Peak(device=device_name, tflops=override_tflops, reason="given with --peak-tflops")
    upper = device_name.upper()
    for pattern, model, tflops in PEAK_BF16_DENSE_TFLOPS:
        if re.search(pattern, upper):
            return Peak(device=device_name, model=model, tflops=tflops, reason=f"{model} datasheet, dense bf16")
    known = ", ".join(m for _, m, _ in PEAK_BF16_DENSE_TFLOPS)
    return Peak(device=device_name, reason=f"no dense bf16 peak known for {device_name!r} (known: {known}); "
                                           "pass --peak-tflops for an MFU")


def head_params(config: Any) -> int:
    """Parameters of the LM head matrix (vocab x hidden); multimodal configs keep them in text_config."""
    text = getattr(config, "text_config", None) or config
    return int(text.vocab_size) * int(text.hidden_size)


def learner_step_flops(n_params: int, n_head: int, tokens: int, loss_tokens: int, *, reference: bool = True) -> float:
    """Matmul FLOPs of learner steps over `tokens` positions of which `loss_tokens` are trained."""
    if not 0 <= n_head <= n_params:
        raise ValueError(f"n_head={n_head} must be within [0, n_params={n_params}]")
    if not 0 <= loss_tokens <= tokens:
        raise ValueError(f"loss_tokens={loss_tokens} must be within [0, tokens={tokens}]")
    passes = 6 + (2 if reference else 0)
    return float(passes * (n_params - n_head) * tokens + passes * n_head * loss_tokens)


def mfu(flops: float, seconds: float, peak: Peak) -> float | None:
    return None if peak.tflops is None or seconds <= 0 else flops / seconds / (peak.tflops * 1e12)


def resolve_vllm_python(setting: str) -> str:
    """The interpreter of the vLLM half: a path, or "auto" (this one if it imports vllm, else the
    project's .venv-vllm, else the cluster nodes' ~/hcgym-vllm)."""
    if setting != "auto":
        path = Path(setting).expanduser()
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise ValueError(f"--vllm-python: {setting!r} is not an executable file")
        return str(path)
    import importlib.util

    if importlib.util.find_spec("vllm") is not None:
        return sys.executable
    for candidate in (ROOT / ".venv-vllm" / "bin" / "python", Path("~/hcgym-vllm/bin/python").expanduser()):
        if candidate.exists():
            return str(candidate)
    raise ValueError("--vllm-python auto: this interpreter has no vllm, and neither .venv-vllm/bin/python nor "
                     "~/hcgym-vllm/bin/python exists; pass --vllm-python PATH")


class FigureLog:
    """Figures of a run, printed and written to `path` (JSON) as each phase ends, so a later failure
    keeps what was measured. The file is replaced atomically after every phase."""

    def __init__(self, path: str | Path | None, header: dict[str, Any] | None = None):
        self.path = Path(path) if path else None
        self.data: dict[str, Any] = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **(header or {}),
                                     "phases": {}}
        self._write()

    def record(self, phase: str, figures: dict[str, Any]) -> None:
        self.data["phases"][phase] = figures
        print(f"PHASE {phase} {json.dumps(figures, default=str)}", flush=True)
        self._write()

    def set(self, key: str, value: Any) -> None:
        self.data[key] = value
        self._write()

    def _write(self) -> None:
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(self.path.suffix + ".tmp")
        tmp.write_text(json.dumps(self.data, indent=1, default=str))
        os.replace(tmp, self.path)
