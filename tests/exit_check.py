"""Run the teardown-heavy part of the suite N times, each in a fresh pytest process, and fail on any
non-zero exit (`make exit-check`, or `.venv/bin/python tests/exit_check.py -n 10`).

A crash while the interpreter exits is rare (one full `make test` in two died with SIGSEGV after
"2141 passed"), so one green run says little: this repeats a subset that starts, in the pytest
process, what the suite starts there (a local Ray cluster three times over, gloo process groups and
TCP stores, the KB's numba kernel and tantivy index, the gc-frozen ICD-10/HPO indexes, a simulated
Ray cluster in a child pytest) and reports every exit code. Each run has
PYTHONFAULTHANDLER=1 (a crash prints every thread's Python stack) and core dumps on in its own
folder; when a run dies of a signal and gdb is installed, the native stack of every thread is
written next to the report, which is where a crash in a C++ thread shows itself.

Usage: tests/exit_check.py [-n RUNS] [--out DIR] [pytest paths or options ...]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]

# Sized to stay under 2 minutes a run on 2 cores. Ray is started and shut down three times (evals'
# module cluster, the KB service's, the KB API errors test's), gloo groups and TCP stores live in the
# pytest process (weight sync), the ICD-10 / HPO indexes are gc-frozen (clinical diagnosis tools), and
# tests/core/test_exit.py runs a simulated two-node Ray cluster in a child pytest.
DEFAULT_SUBSET = (
    "tests/kb/test_service.py",
    "tests/kb/test_kb_api_errors.py",
    "tests/training/test_learner_weight_sync.py",
    "tests/evals/test_runner.py::test_ray_pool_gives_the_plain_loop_results",
    "tests/domains/test_clinical_diagnosis.py",
    "tests/core/test_exit.py",
)

CPU_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "TOKENIZERS_PARALLELISM": "false",
           "RAY_USAGE_STATS_ENABLED": "0", "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1",
           "DS_ACCELERATOR": "cpu"}


def _allow_core_dumps() -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_CORE)
    resource.setrlimit(resource.RLIMIT_CORE, (hard, hard))


def _native_stacks(core: Path, out: Path) -> str:
    gdb = shutil.which("gdb")
    if gdb is None:
        return f"core file {core} kept (no gdb to read it)"
    with out.open("w") as fh:
        subprocess.run([gdb, "-batch", "-ex", "set pagination off", "-ex", "thread apply all bt 40",
                        sys.executable, str(core)], stdout=fh, stderr=subprocess.STDOUT, timeout=300, check=False)
    return f"native stacks of every thread: {out}"


def _fault_dump(output: str) -> str:
    start = output.find("Fatal Python error")
    return output[start:start + 6000] if start >= 0 else ""


def run_once(index: int, args: list[str], out_dir: Path) -> tuple[int, float, str]:
    work = out_dir / f"run{index:03d}"
    work.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, **CPU_ENV, "PYTHONFAULTHANDLER": "1"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_ROOT), env.get("PYTHONPATH", "")) if p)
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(REPO_ROOT),
               "-c", str(REPO_ROOT / "pyproject.toml"), *args]
    start = time.monotonic()
    # cwd is the run's own folder: with the usual core_pattern ("core") a core dump lands there.
    proc = subprocess.run(command, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          errors="replace", preexec_fn=_allow_core_dumps, check=False)
    seconds = time.monotonic() - start
    (work / "output.txt").write_text(proc.stdout)
    notes = []
    if proc.returncode != 0:
        summary = [line for line in proc.stdout.splitlines() if " passed" in line or " failed" in line]
        notes.append(f"pytest said: {summary[-1] if summary else '(no summary line)'}")
        dump = _fault_dump(proc.stdout)
        if dump:
            notes.append(f"fault dump:\n{dump}")
        for core in sorted(work.glob("core*")):
            notes.append(_native_stacks(core, work / f"{core.name}.stacks.txt"))
    else:
        shutil.rmtree(work)
    return proc.returncode, seconds, "\n".join(notes)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--runs", type=int, default=5, help="fresh pytest processes to run (default 5)")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for the output of failed runs (default: a new temporary folder)")
    args, pytest_args = parser.parse_known_args(argv)
    if args.runs < 1:
        parser.error(f"--runs must be at least 1, got {args.runs}")
    # Paths are given relative to the repository (each run's working directory is its own folder).
    pytest_args = [f"{REPO_ROOT}/{a}" if not a.startswith("-") and (REPO_ROOT / a.split("::")[0]).exists() else a
                   for a in pytest_args or DEFAULT_SUBSET]
    out_dir = args.out or Path(tempfile.mkdtemp(prefix="hcgym-exit-check-"))
    print(f"exit check: {args.runs} fresh pytest processes of: {' '.join(pytest_args)}", flush=True)
    failures = 0
    for index in range(1, args.runs + 1):
        code, seconds, notes = run_once(index, pytest_args, out_dir)
        name = f" ({signal.Signals(-code).name})" if code < 0 and -code in signal.Signals._value2member_map_ else ""
        print(f"run {index}/{args.runs}: exit {code}{name} in {seconds:.0f} s", flush=True)
        if code != 0:
            failures += 1
            print(notes, flush=True)
    print(f"exit check: {args.runs - failures}/{args.runs} runs exited 0"
          + (f"; output of the failed runs in {out_dir}" if failures else ""), flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
