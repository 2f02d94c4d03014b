"""Run-config files for tests: a shipped config extended by a few keys, as a user writes one."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def extended_config(tmp_path: Path, body: str, base: str = "tiny_cpu_grpo.yaml") -> Path:
    """`tmp_path/run.yaml`: `extends: configs/<base>` followed by `body` (YAML text)."""
    path = tmp_path / "run.yaml"
    path.write_text(f"extends: {REPO / 'configs' / base}\n{body}\n")
    return path
