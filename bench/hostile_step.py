"""The cost of one hostile action: one 99 KB action of 3,300 `lookup_drug` calls
with unknown names (each call asks for "did you mean" suggestions over the 11,239-name drug index),
measured in one run under three settings:

  * the baseline: every call runs, suggestions by `difflib.get_close_matches`
    over the whole index per call;
  * uncapped with the index: every call runs, suggestions from `envs.core.fuzzy` (same answers);
  * the env as it is: at most MAX_CALLS_PER_ACTION calls run (the rest refused), indexed suggestions.

    python bench/hostile_step.py [--calls 3300] [--repeats 3]
"""

from __future__ import annotations

import argparse
import difflib
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def step_seconds(calls: int, repeats: int) -> tuple[float, int, str]:
    """(median seconds of the step, calls run, the observation)."""
    from envs.env import HealthcareGymEnv

    action = "\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(calls))
    times, ran, first = [], 0, ""
    for _ in range(repeats):
        env = HealthcareGymEnv(domain="drug_interaction", max_turns=3, step_time_budget_s=None)
        env.reset(seed=0)
        started = time.perf_counter()
        observation, _, _, _, info = env.step(action)
        times.append(time.perf_counter() - started)
        ran, first = len(info["tool_calls"]), observation
    return statistics.median(times), ran, first


def difflib_suggestions(word, names, n=3, cutoff=0.6):
    """The per-call scan the index replaced (for the baseline only)."""
    return difflib.get_close_matches(word, list(names), n, cutoff)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=3300)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import envs  # noqa: F401  (runtime defaults)
    import envs.env as env_module
    import envs.domains.drug_interaction.logic as logic

    capped, ran_capped, first_capped = step_seconds(args.calls, args.repeats)
    cap = env_module.MAX_CALLS_PER_ACTION
    env_module.MAX_CALLS_PER_ACTION = 10**9  # every call runs
    try:
        indexed, ran_indexed, first_indexed = step_seconds(args.calls, 1)
        indexed_suggestions = logic.close_matches
        logic.close_matches = difflib_suggestions
        try:
            baseline, ran_baseline, first_baseline = step_seconds(args.calls, 1)
        finally:
            logic.close_matches = indexed_suggestions
    finally:
        env_module.MAX_CALLS_PER_ACTION = cap
    assert first_baseline == first_indexed  # the same observation, suggestions included, both ways
    size = len("\n".join(f'lookup_drug(name="zq{i:04d}xkv")' for i in range(args.calls)))
    print(f"one action of {args.calls} unknown-drug lookups ({size / 1000:.0f} KB), drug_interaction")
    print(f"  before (uncapped, difflib scan): {baseline:8.3f} s  ({ran_baseline} calls run)")
    print(f"  uncapped, indexed suggestions:   {indexed:8.3f} s  ({ran_indexed} calls run)")
    print(f"  now (cap {cap}, indexed):          {capped:8.3f} s  ({ran_capped} calls run; median of {args.repeats})")
    print(f"  per unknown name: {baseline / ran_baseline * 1000:.2f} ms with difflib, "
          f"{indexed / ran_indexed * 1000:.2f} ms indexed ({baseline / indexed:.0f}x)")
    print(f"  ratio before / now: {baseline / capped:.0f}x")
    print(f"  first observation line (the same observation both ways): {first_capped.splitlines()[0][:160]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
