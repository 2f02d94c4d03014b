"""The cost of one hostile action: issue 13's reproducer, one 99 KB action of 3,300 `lookup_drug` calls
with unknown names (each call fuzzy-matches the whole drug-name index), with the env's cap of
MAX_CALLS_PER_ACTION calls per action against the same env with the cap lifted (the baseline, as the
env behaved before the cap), in the same run.

    python bench/hostile_step.py [--calls 3300] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def step_seconds(calls: int, repeats: int) -> tuple[float, int]:
    from envs.core.env import HealthcareGymEnv

    action = "\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(calls))
    times, ran = [], 0
    for _ in range(repeats):
        env = HealthcareGymEnv(domain="drug_interaction", max_turns=3)
        env.reset(seed=0)
        started = time.perf_counter()
        _, _, _, _, info = env.step(action)
        times.append(time.perf_counter() - started)
        ran = len(info["tool_calls"])
    return statistics.median(times), ran


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=3300)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import envs  # noqa: F401  (runtime defaults)
    import envs.core.env as env_module

    capped, ran_capped = step_seconds(args.calls, args.repeats)
    cap = env_module.MAX_CALLS_PER_ACTION
    env_module.MAX_CALLS_PER_ACTION = 10**9  # the baseline: every call runs
    try:
        uncapped, ran_uncapped = step_seconds(args.calls, 1)
    finally:
        env_module.MAX_CALLS_PER_ACTION = cap
    size = len("\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(args.calls)))
    print(f"one action of {args.calls} unknown-drug lookups ({size / 1000:.0f} KB), drug_interaction")
    print(f"  capped at {cap} calls:  {capped:8.3f} s  ({ran_capped} calls run; median of {args.repeats})")
    print(f"  uncapped (baseline): {uncapped:8.3f} s  ({ran_uncapped} calls run)")
    print(f"  ratio uncapped / capped: {uncapped / capped:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
