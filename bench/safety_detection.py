"""Safety detection: detection rate and false-alarm rate of the reward's safety detector on the
guideline-written set (`tests/fixtures/safety/trajectories.json`: dangerous and safe trajectories,
each citing its guideline or US label), against the detector of an earlier revision run on the
same cases in the same run.

    python bench/safety_detection.py [--baseline-rev 749e5f4] [--no-baseline] [--json out.json]

A dangerous case is detected when every pattern it expects is reported; a safe case is a false
alarm when any violation is reported. The baseline revision's code (envs/ and tests/) is
exported with `git archive` into a temporary folder and runs the same cases in a subprocess; a
pattern that did not exist at that revision counts as not detected. The default baseline,
749e5f4, is the detector before the guideline-cited patterns and the safety set were added.
Per-episode detector time is printed for both; the cases were written by the engineer who changed
the detector, so the current rates are not a held-out estimate (see docs/rewards.md).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tarfile
import tempfile
import time
from collections import defaultdict
from io import BytesIO
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.rewards.test_safety_set import SET_FILE, load_cases, rates, run_case  # noqa: E402 (needs ROOT on sys.path)

DEFAULT_BASELINE = "749e5f4"

# Runs inside the exported baseline tree: the same construction as tests/rewards/test_safety_set.build.
_BASELINE_SCRIPT = r'''
import json, sys, time
from envs.core.task import Task
from envs.rewards import StaticSafetyContext, detect_violations
from tests.rewards.builders import call, episode, turn
cases = json.load(open(sys.argv[1], encoding="utf-8"))["cases"]
chart = {"name": "get_patient_info", "arguments": {"patient_id": "P1"}, "result": '{"id": "P1"}'}
out, spent = [], 0.0
for c in cases:
    fields = {"patient_id": "P1", "domain": "ward", **c.get("task", {})}
    task = Task(id="safety-set-" + c["id"], ticket=c["ticket"], emergency=c.get("emergency"), **fields)
    calls = ([chart] if task.patient_id else []) + c.get("calls", [])
    turns = [turn(call(x["name"], x.get("arguments", {}), result=x.get("result", "ok"))) for x in calls]
    traj = episode(task, *turns, answer=c["answer"])
    p = c.get("patient", {})
    ctx = StaticSafetyContext(allergies={"P1": p.get("allergies", [])}, medications={"P1": p.get("medications", [])},
                              conditions={"P1": p.get("conditions", [])})
    t0 = time.perf_counter()
    violations, errors = detect_violations(traj, task, ctx)
    spent += time.perf_counter() - t0
    out.append({"id": c["id"], "found": sorted({v.pattern_id for v in violations})})
print(json.dumps({"results": out, "seconds": spent}))
'''


def current() -> tuple[list[dict], float]:
    cases = load_cases()
    results, spent = [], 0.0
    for case in cases:
        t0 = time.perf_counter()
        results.append(run_case(case))
        spent += time.perf_counter() - t0
    return results, spent


def baseline(rev: str) -> tuple[list[dict], float]:
    archive = subprocess.run(["git", "archive", "--format=tar", rev, "envs", "tests"], cwd=ROOT, capture_output=True, check=False)
    if archive.returncode != 0:
        raise SystemExit(f"git archive {rev} failed: {archive.stderr.decode(errors='replace').strip()}")
    cases = {c.id: c for c in load_cases()}
    with tempfile.TemporaryDirectory(prefix="safety-baseline-") as tmp:
        with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
            tar.extractall(tmp, filter="data")
        proc = subprocess.run([sys.executable, "-c", _BASELINE_SCRIPT, str(SET_FILE)], cwd=tmp, capture_output=True,
                              text=True, env={"PYTHONPATH": tmp, "PATH": "/usr/bin:/bin", "HF_HUB_OFFLINE": "1",
                                              "TRANSFORMERS_OFFLINE": "1", "OMP_NUM_THREADS": "1"}, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"baseline {rev} failed:\n{proc.stderr[-2000:]}")
    payload = json.loads(proc.stdout.strip().splitlines()[-1])
    results = []
    for row in payload["results"]:
        case = cases[row["id"]]
        ok = set(case.expect) <= set(row["found"]) if case.kind == "dangerous" else not row["found"]
        results.append({"id": case.id, "kind": case.kind, "ok": ok, "found": row["found"], "expect": case.expect})
    return results, payload["seconds"]


def by_group(results: list[dict]) -> dict[str, tuple[int, int]]:
    """(ok, total) per group: the expected pattern family for dangerous cases."""
    groups: dict[str, list[bool]] = defaultdict(list)
    for r in results:
        if r["kind"] == "dangerous":
            family = r["expect"][0].split(".")[0]
            groups[family].append(r["ok"])
    return {k: (sum(v), len(v)) for k, v in sorted(groups.items())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline-rev", default=DEFAULT_BASELINE)
    parser.add_argument("--no-baseline", action="store_true")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()

    now, now_s = current()
    runs = {"current": (now, now_s)}
    if not args.no_baseline:
        runs[f"baseline {args.baseline_rev}"] = baseline(args.baseline_rev)
    summary = {}
    print(f"safety set: {SET_FILE.relative_to(ROOT)}")
    print(f"{'detector':<20} {'detected':>10} {'det. rate':>10} {'false alarms':>13} {'FA rate':>8} {'ms/episode':>11}")
    for name, (results, seconds) in runs.items():
        r = rates(results)
        ms = 1000 * seconds / max(1, len(results))
        summary[name] = {**r, "ms_per_episode": ms, "groups": by_group(results),
                         "misses": [x["id"] for x in results if x["kind"] == "dangerous" and not x["ok"]],
                         "false_alarm_cases": {x["id"]: x["found"] for x in results if x["kind"] == "safe" and not x["ok"]}}
        print(f"{name:<20} {r['detected']:>4}/{r['dangerous']:<5} {r['detection_rate']:>10.1%} {r['false_alarms']:>6}/{r['safe']:<6}"
              f" {r['false_alarm_rate']:>8.1%} {ms:>11.2f}")
    for name, s in summary.items():
        print(f"\n{name}: detected per pattern family: " + ", ".join(f"{k} {a}/{b}" for k, (a, b) in s["groups"].items()))
        if s["misses"]:
            print(f"  missed: {', '.join(s['misses'])}")
        for cid, found in s["false_alarm_cases"].items():
            print(f"  false alarm {cid}: {', '.join(found)}")
    if len(runs) == 2:
        cur, base = summary["current"], summary[f"baseline {args.baseline_rev}"]
        print(f"\ndetection rate {base['detection_rate']:.1%} -> {cur['detection_rate']:.1%}; "
              f"false-alarm rate {base['false_alarm_rate']:.1%} -> {cur['false_alarm_rate']:.1%}; "
              f"time per episode x{cur['ms_per_episode'] / max(1e-9, base['ms_per_episode']):.2f} of the baseline")
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
