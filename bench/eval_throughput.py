"""Evaluation-harness throughput with a scripted policy: the Ray env-actor pool vs a plain
in-process loop, on the same episodes, with identical results.

The policy is scripted (`scripted:gold` by default: the env executes the gold tool calls and
scores the submitted answer; no model), so the figures measure the harness itself: env reset and
steps, tools, grading, the conditions' bookkeeping, the Parquet writes and, for Ray, the actor
round trips. The plain loop runs one episode at a time in this process (`use_ray=False`,
concurrency 1); the pool runs `--actors` env actors with `--slots` episodes each in flight. Actor
start-up is excluded (the pool is started and warmed up first). Every row of the two runs must
be identical apart from its latency, else the script fails.

    python bench/eval_throughput.py [--domain triage_emergency] [--split test] [--seeds 2]
        [--policy scripted:gold] [--condition agent] [--actors 2] [--slots 8] [--json out.json]

With `--endpoint openai:BASE_URL:MODEL` (a running OpenAI-compatible server, e.g. vLLM's CPU build
serving a model) it measures the harness against the endpoint instead: the same episodes with one
request in flight vs `--concurrency` in flight (in-process envs), and counts the episodes whose
answers differ (a server may batch differently; the rows' keys must match exactly).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: F401  (CPU runtime defaults)


def comparable(rows) -> list[str]:
    return sorted(json.dumps(r.model_dump(exclude={"latency_s"}), sort_keys=True) for r in rows)


async def pooled(policy, items, out, options, actors: int, slots: int, env_vars) -> float:
    from actors.env_actor import EnvPool
    from evals.runner import run_episodes

    pool = EnvPool(actors, slots, options.settings.max_turns, env_vars=env_vars)
    await pool.ready()
    # Warm-up on a throwaway folder: first imports and env construction in every actor.
    await run_episodes(policy, items[: actors * 2], out.parent / "warmup",
                       options.__class__(**{**options.__dict__, "env_pool": pool}))
    t0 = time.perf_counter()
    await run_episodes(policy, items, out, options.__class__(**{**options.__dict__, "env_pool": pool}))
    return time.perf_counter() - t0


def bench_items(args):
    from envs import registry
    from evals.types import EvalItem

    tasks = registry.get_tasks(args.domain, args.split)[: args.limit]
    return [EvalItem(benchmark=f"{args.domain}_{args.split}", domain=args.domain, task_id=t.id, split=args.split)
            for t in tasks]


def endpoint_main(args) -> int:
    """Episodes/s against a live endpoint: 1 request in flight vs `--concurrency`."""
    from evals.conditions import ConditionSettings
    from evals.policies import resolve_policy
    from evals.runner import EvalOptions, run_eval
    from evals.types import read_results

    items = bench_items(args)
    root = Path(tempfile.mkdtemp(prefix="bench_eval_endpoint_"))
    rates, rows = {}, {}
    # Warm-up over the same episodes: the server's first-request costs and its prefix cache then
    # favour neither measured pass.
    warm, _ = resolve_policy(args.endpoint, concurrency=args.concurrency)
    run_eval(warm, items, root / "warmup", EvalOptions(condition=args.condition, seeds=tuple(range(args.seeds)),
                                                       use_ray=False, concurrency=args.concurrency, progress=False,
                                                       settings=ConditionSettings(max_turns=5)))
    for concurrency in (1, args.concurrency):
        policy, _ = resolve_policy(args.endpoint, concurrency=concurrency)
        options = EvalOptions(condition=args.condition, seeds=tuple(range(args.seeds)), use_ray=False,
                              concurrency=concurrency, progress=False, settings=ConditionSettings(max_turns=5))
        t0 = time.perf_counter()
        run_eval(policy, items, root / f"c{concurrency}", options)
        rates[concurrency] = len(items) * args.seeds / (time.perf_counter() - t0)
        rows[concurrency] = {r.key(): r for r in read_results(root / f"c{concurrency}")}
    one, many = rows[1], rows[args.concurrency]
    if set(one) != set(many):
        print("FAIL: the two runs hold different episodes", file=sys.stderr)
        return 1
    differ = sum(one[k].answer != many[k].answer for k in one)
    errors = sum(r.end_reason in ("endpoint_error", "context_overflow") for r in many.values())
    result = {"endpoint": args.endpoint, "domain": args.domain, "condition": args.condition, "episodes": len(one),
              "episodes_per_s_concurrency_1": rates[1], f"episodes_per_s_concurrency_{args.concurrency}":
              rates[args.concurrency], "speedup": rates[args.concurrency] / rates[1], "answers_differ": differ,
              "endpoint_or_context_errors": errors}
    print(f"{len(one)} episodes ({args.domain}/{args.split}, {args.condition}) against {args.endpoint}")
    print(f"  1 request in flight : {rates[1]:8.2f} episodes/s")
    print(f"  {args.concurrency} requests in flight: {rates[args.concurrency]:8.2f} episodes/s "
          f"({result['speedup']:.2f}x); answers differing: {differ}; errors: {errors}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--domain", default="triage_emergency")
    parser.add_argument("--split", default="test")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--policy", default="scripted:gold")
    parser.add_argument("--condition", default="agent", choices=("text", "logprob", "agent"))
    parser.add_argument("--actors", type=int, default=2)
    parser.add_argument("--slots", type=int, default=8)
    parser.add_argument("--json", default=None)
    parser.add_argument("--endpoint", default=None, help="openai:BASE_URL:MODEL of a running server")
    parser.add_argument("--concurrency", type=int, default=8, help="endpoint mode: requests in flight")
    parser.add_argument("--limit", type=int, default=None, help="at most N tasks")
    args = parser.parse_args(argv)
    if args.endpoint:
        return endpoint_main(args)

    import ray

    from evals.conditions import ConditionSettings
    from evals.policies import resolve_policy
    from evals.runner import EvalOptions, run_eval
    from evals.types import read_results

    items = bench_items(args)
    policy, _ = resolve_policy(args.policy)
    env_vars = {"HCGYM_EMBEDDINGS": os.environ.get("HCGYM_EMBEDDINGS", "0")}
    os.environ.update(env_vars)
    root = Path(tempfile.mkdtemp(prefix="bench_eval_"))
    base = dict(condition=args.condition, seeds=tuple(range(args.seeds)), settings=ConditionSettings(max_turns=5),
                progress=False, flush_every_s=2.0, env_vars=env_vars)
    episodes = len(items) * args.seeds

    # Plain loop: one episode at a time, in this process.
    run_eval(policy, items[:2], root / "plain_warmup", EvalOptions(use_ray=False, concurrency=1, **base))
    t0 = time.perf_counter()
    run_eval(policy, items, root / "plain", EvalOptions(use_ray=False, concurrency=1, **base))
    plain_s = time.perf_counter() - t0

    from envs._runtime import init_ray  # a local cluster on 127.0.0.1 only

    init_ray("local", include_dashboard=False, log_to_driver=False, runtime_env={"env_vars": env_vars})
    try:
        options = EvalOptions(use_ray=True, concurrency=args.actors * args.slots, **base)
        ray_s = asyncio.run(pooled(policy, items, root / "ray", options, args.actors, args.slots, env_vars))
    finally:
        ray.shutdown()

    plain_rows, ray_rows = read_results(root / "plain"), read_results(root / "ray")
    identical = comparable(plain_rows) == comparable(ray_rows)
    correct = sum(bool(r.correct) for r in plain_rows)
    result = {"domain": args.domain, "split": args.split, "policy": args.policy, "condition": args.condition,
              "episodes": episodes, "correct": correct, "plain_episodes_per_s": episodes / plain_s,
              "ray_episodes_per_s": episodes / ray_s, "ray_over_plain": plain_s / ray_s,
              "actors": args.actors, "slots": args.slots, "identical": identical, "cpus": os.cpu_count()}
    print(f"{episodes} episodes ({args.domain}/{args.split}, {args.policy}, {args.condition}; {correct} correct)")
    print(f"  plain loop      : {result['plain_episodes_per_s']:8.1f} episodes/s")
    print(f"  Ray {args.actors} actors x {args.slots} slots: {result['ray_episodes_per_s']:8.1f} episodes/s")
    print(f"  ratio Ray / plain: {result['ray_over_plain']:.2f}x   identical results: {identical}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    if not identical:
        print("FAIL: the Ray pool and the plain loop disagree on some rows", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
