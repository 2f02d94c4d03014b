"""The demo's claim, measured: held-out reward after RL vs the SFT warm start, over several seeds.

Runs `hcgym train --config CONFIG --seed S --output-dir OUT/seed_S` for each seed (unless the run
directory already has a finished `validation.jsonl` and `--summarise-only` is given), then prints,
per seed, the held-out reward of the warm start (validation at step 0) and after RL (the last
validation), their paired difference, and whether the mean gain exceeds the seed-to-seed noise
(the standard deviation across seeds of the warm start's held-out reward, and of the gain).

    python bench/demo_seeds.py [--config configs/tiny_cpu_ttopd.yaml] [--seeds 0 1 2] [--out runs/demo_seeds]
        [--set KEY.PATH=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
METRICS = ("val_reward_component/total", "val_reward_mean", "val_accuracy", "val_truncated_frac", "val_tool_calls_mean")


def validations(run_dir: Path) -> list[dict]:
    path = run_dir / "validation.jsonl"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no validation record (did the run finish?)")
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    if len(rows) < 2 or rows[0].get("step") != 0:
        raise ValueError(f"{path}: need a step-0 (warm start) and a later validation, found steps "
                         f"{[r.get('step') for r in rows]}")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="configs/tiny_cpu_ttopd.yaml")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default="runs/demo_seeds")
    ap.add_argument("--metric", default="val_reward_component/total",
                    help="the held-out reward compared (default: the 5D total)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="a config override passed to every run (repeatable), e.g. generator.backend=vllm")
    ap.add_argument("--summarise-only", action="store_true", help="read existing run directories, train nothing")
    ap.add_argument("--json", help="also write the summary here")
    args = ap.parse_args(argv)

    out = Path(args.out)
    walls = {}
    for seed in args.seeds:
        run_dir = out / f"seed_{seed}"
        if args.summarise_only:
            continue
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "learner.train", "--config", args.config, "--seed", str(seed),
               "--output-dir", str(run_dir)]
        for item in args.overrides:
            cmd += ["--set", item]
        print(f"[demo_seeds] seed {seed}: {' '.join(cmd)}", flush=True)
        subprocess.run(cmd, cwd=ROOT, check=True)
        walls[seed] = time.perf_counter() - t0

    rows = []
    for seed in args.seeds:
        vals = validations(out / f"seed_{seed}")
        first, last = vals[0], vals[-1]
        rows.append({"seed": seed, "final_step": last["step"], "wall_s": walls.get(seed),
                     **{f"warm/{m}": first.get(m) for m in METRICS}, **{f"rl/{m}": last.get(m) for m in METRICS}})
    m = args.metric
    warm = [r[f"warm/{m}"] for r in rows]
    final = [r[f"rl/{m}"] for r in rows]
    gains = [b - a for a, b in zip(warm, final)]
    print(f"\n| seed | warm start | after RL (step) | gain | accuracy warm -> RL | truncated warm -> RL |")
    print("|---|---|---|---|---|---|")
    for r, g in zip(rows, gains):
        print(f"| {r['seed']} | {r[f'warm/{m}']:.3f} | {r[f'rl/{m}']:.3f} ({r['final_step']}) | {g:+.3f} | "
              f"{r['warm/val_accuracy']:.3f} -> {r['rl/val_accuracy']:.3f} | "
              f"{r['warm/val_truncated_frac']:.2f} -> {r['rl/val_truncated_frac']:.2f} |")
    sd = (lambda xs: statistics.stdev(xs) if len(xs) > 1 else float("nan"))
    summary = {"metric": m, "seeds": args.seeds, "warm_mean": statistics.mean(warm), "warm_sd": sd(warm),
               "rl_mean": statistics.mean(final), "rl_sd": sd(final), "gain_mean": statistics.mean(gains),
               "gain_sd": sd(gains), "gain_min": min(gains), "rows": rows}
    noise = max(summary["warm_sd"], summary["gain_sd"]) if len(gains) > 1 else float("nan")
    summary["exceeds_noise"] = bool(summary["gain_mean"] > noise and summary["gain_min"] > 0)
    print(f"\n{m}: warm start {summary['warm_mean']:.3f} +- {summary['warm_sd']:.3f}, after RL "
          f"{summary['rl_mean']:.3f} +- {summary['rl_sd']:.3f}; gain {summary['gain_mean']:+.3f} +- "
          f"{summary['gain_sd']:.3f} (min {summary['gain_min']:+.3f}); seed-to-seed noise {noise:.3f}: "
          f"{'gain exceeds it on every seed' if summary['exceeds_noise'] else 'gain does NOT exceed it'}")
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
