"""Environment step overhead: env.step on a READ tool call vs calling the same tool directly.

For every registered domain: reset latency (median), steps/s for a READ tool call, and the
environment's overhead per step (parse + validate + record) = median step time - median direct
call time of the same tool function with the same arguments. Target: <= 100 microseconds.
"The tool's own work" is calling the function and serialising its result to the observation text.
Also reports the slowest tool of each domain over the gold actions of its tasks, median of three
warm calls (target <= 5 ms except knowledge search; one-off index loads on first use excluded).

Run: python bench/env_step.py [--domains a b] [--steps 3000]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: E402,F401
from envs import registry  # noqa: E402
from envs.core.env import HealthcareGymEnv  # noqa: E402
from envs.core.tools import ToolType  # noqa: E402

KNOWLEDGE_TOOLS = {"search", "search_pubmed", "retrieve_evidence", "search_medical_wiki", "browse_article",
                   "search_guidelines"}


def _median_us(samples: list[float]) -> float:
    return statistics.median(samples) * 1e6


def pick_read_action(domain: str):
    """The first READ expected action of any task (tools are looked up after reset, since some
    domains, e.g. cross-domain pathways, build their toolkit per task)."""
    env = HealthcareGymEnv(domain=domain, max_turns=10**9)
    for task in registry.get_tasks(domain):
        env.reset(seed=0, options={"task_id": task.id})
        for action in task.evaluation_criteria.actions[:1]:
            definition = env.domain_env.toolkit.definitions.get(action.name)
            if definition and definition.tool_type is ToolType.READ and action.name not in KNOWLEDGE_TOOLS:
                return task, action
    raise SystemExit(f"{domain}: no task with a READ expected action to benchmark")


def slowest_tool(domain: str, max_tasks: int = 150) -> tuple[str, float]:
    """Median of three warm calls of every gold action of up to `max_tasks` tasks."""
    slowest = ("-", 0.0)
    env = HealthcareGymEnv(domain=domain, max_turns=10**9)
    for task in registry.get_tasks(domain)[:max_tasks]:
        env.reset(seed=0, options={"task_id": task.id})
        toolkit = env.domain_env.toolkit
        for action in task.evaluation_criteria.actions:
            if action.name in KNOWLEDGE_TOOLS or action.name not in toolkit.definitions:
                continue
            toolkit.call(action.name, action.arguments)  # warm: one-off index loads are not per-call cost
            runs = []
            for _ in range(3):
                start = time.perf_counter()
                toolkit.call(action.name, action.arguments)
                runs.append(time.perf_counter() - start)
            elapsed = statistics.median(runs)
            if elapsed > slowest[1]:
                slowest = (action.name, elapsed)
    return slowest


def bench_domain(domain: str, steps: int) -> dict:
    task, action = pick_read_action(domain)
    env = HealthcareGymEnv(domain=domain, task_id=task.id, max_turns=10**9)
    resets = []
    for seed in range(200):
        start = time.perf_counter()
        env.reset(seed=seed)
        resets.append(time.perf_counter() - start)
    env.reset(seed=0)
    text = "<tool_call>" + json.dumps({"name": action.name, "arguments": action.arguments}) + "</tool_call>"
    definition, method = env.domain_env.toolkit.bound(action.name)
    kwargs = definition.validate(action.arguments)
    direct, stepped = [], []
    for _ in range(steps):
        # The tool's own work: compute the result and serialise it to the observation text the
        # agent must receive. Everything else in env.step (parse, validate, record) is overhead.
        start = time.perf_counter()
        json.dumps(method(**kwargs), ensure_ascii=False, default=str)
        direct.append(time.perf_counter() - start)
        start = time.perf_counter()
        env.step(text)
        stepped.append(time.perf_counter() - start)
        if len(env._record.turns) > 200:  # keep the transcript from growing without bound
            env.reset(seed=0)
    slowest = slowest_tool(domain)
    step_us, direct_us = _median_us(stepped), _median_us(direct)
    return {
        "domain": domain, "tool": action.name, "reset_ms_p50": _median_us(resets) / 1000,
        "step_us_p50": step_us, "direct_us_p50": direct_us, "overhead_us": step_us - direct_us,
        "steps_per_s": 1e6 / step_us, "step_over_direct_ratio": step_us / max(direct_us, 1e-3),
        "slowest_tool": slowest[0], "slowest_tool_ms": slowest[1] * 1000,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domains", nargs="*")
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
    rows = [bench_domain(d, args.steps) for d in (args.domains or registry.list_domains())]
    header = f"{'domain':18s} {'tool':28s} {'reset ms':>9s} {'step us':>9s} {'direct us':>9s} {'overhead us':>11s} {'steps/s':>9s} {'step/direct':>11s} {'slowest tool (ms)':>28s}"
    print(header)
    for r in rows:
        print(f"{r['domain']:18s} {r['tool']:28s} {r['reset_ms_p50']:9.3f} {r['step_us_p50']:9.1f} {r['direct_us_p50']:9.1f} "
              f"{r['overhead_us']:11.1f} {r['steps_per_s']:9.0f} {r['step_over_direct_ratio']:11.1f} "
              f"{r['slowest_tool'] + ' ' + format(r['slowest_tool_ms'], '.3f'):>28s}")
    worst = max(r["overhead_us"] for r in rows)
    print(f"\nworst env overhead per step: {worst:.1f} us (target <= 100 us): {'PASS' if worst <= 100 else 'FAIL'}")


if __name__ == "__main__":
    main()
