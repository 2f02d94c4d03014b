"""bench/gpu_check.py, the one-script GPU check, rehearsed on CPU.

The full rehearsal (`--cpu`, all five phases: vLLM CPU engine, DeepSpeed on CPU, Ray) takes minutes
on two cores, beyond this file's share of the suite; here the real script runs the env and
weight_sync phases end to end, and the smoke/step/twin phases through their skip path (a vLLM
interpreter without vLLM), which checks their plumbing: each phase's entry in the JSON, the reason,
and what to carry. docs/benchmarks.md ("GPU check") records the full rehearsal's timing.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import gpu_check  # noqa: E402


def test_missing_packages_name_what_to_carry_or_why_they_cannot_travel():
    env = {"learner": {"python": "/opt/py", "python_version": "3.12.3",
                       "modules": {"torch": "2.11.0", "pydantic": None, "gymnasium": "1.4.0", "ray": None, "deepspeed": None,
                                   "transformers": "5.17.0"}},
           "vllm": {"error": "--vllm-python auto: this interpreter has no vllm"}}
    reasons = gpu_check.missing_for("smoke", env)
    text = "\n".join(reasons)
    assert "pydantic missing in /opt/py" in text and "--python-version 3.12" in text
    assert "deepspeed==0.19.8" in text  # the project's pin (constraints-cpu.txt)
    assert "ray cannot travel" in text and "vllm interpreter unusable" in text
    weight_sync = gpu_check.missing_for("weight_sync", env)
    assert len(weight_sync) == 1 and "pydantic" in weight_sync[0]
    env["learner"]["modules"]["pydantic"] = "2.14.3"
    assert gpu_check.missing_for("weight_sync", env) == []


def test_cpu_rehearsal_writes_every_phase(tmp_path):
    out = tmp_path / "check.json"
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "gpu_check.py"), "--cpu", "--out", str(out),
                           "--vllm-python", sys.executable, "--budget-s", "120"],
                          capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads(out.read_text())
    phases = data["phases"]
    assert list(phases) == gpu_check.PHASES
    assert phases["env"]["learner"]["modules"]["torch"] and phases["env"]["vllm"]["modules"]["vllm"] is None
    ws = phases["weight_sync"]
    assert ws["status"] == "ok", ws
    assert ws["figures"]["bit_exact"] is True and ws["figures"]["transport"] == "gloo-cpu-staged"
    for phase in ("smoke", "step", "twin"):
        assert phases[phase]["status"] == "skipped"
        assert any("vllm missing" in r for r in phases[phase]["reason"]), phases[phase]
    assert "finished" in data
    # Each phase was printed as it ended.
    assert [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("PHASE ")] == gpu_check.PHASES


def test_phase_arguments_are_checked():
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "gpu_check.py"), "--phases", "env,bogus"],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 2 and "unknown ['bogus']" in proc.stderr
