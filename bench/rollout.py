"""Rollout throughput with the scripted gold-replay policy: a plain in-process loop vs the Ray
env-actor pool with 1 and 2 actors, on the same episodes.

The policy is `GoldReplayPolicy` (no model), so the figures measure the rollout machinery itself:
(each mode runs `--repeats` times, the median is reported; actor start-up is excluded)
environment steps, tool execution, grading, TITO tokenization and, for Ray, the actor round trips.
The overhead figure is the Ray pipeline's wall time per episode minus the plain loop's.

    python bench/rollout.py [--domain triage_emergency] [--episodes 96] [--pattern ^tr_calc_] [--json out.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: E402,F401  (CPU runtime defaults)


def build_tokenizer(domain: str, pattern: str | None) -> object:
    from learner.model import load_tokenizer, train_tokenizer
    from learner.sft import task_corpus

    out = Path(tempfile.mkdtemp(prefix="bench_rollout_tok_"))
    train_tokenizer(task_corpus([domain], "train", pattern), 2048, out, max_stdlib_files=40)
    return load_tokenizer(out)


def specs(refs, n):
    from actors.agent_loop import EpisodeSpec

    return [EpisodeSpec(sample_id=f"{refs[i % len(refs)].task_id}:{i}:{i}", task_id=refs[i % len(refs)].task_id,
                        domain=refs[i % len(refs)].domain, split=refs[i % len(refs)].split, group_id=f"b{i}", seed=i)
            for i in range(n)]


async def plain_loop(loop, policy, episode_specs, max_turns):
    from actors.agent_loop import LocalEnv

    env = LocalEnv(max_turns)
    return [await loop.run(spec, env, policy) for spec in episode_specs]


async def ray_pool(loop, policy, episode_specs, max_turns, actors, slots, env_vars):
    import ray

    from actors.env_actor import EnvPool, EpisodeLedger, run_episode

    pool = EnvPool(actors, slots, max_turns, env_vars=env_vars)
    await pool.ready()
    # Warm-up: one episode per actor, so actor start and first imports are not timed.
    warm = EpisodeLedger()
    for spec in episode_specs[:actors]:
        warm.admit(spec.sample_id)
    await asyncio.gather(*[run_episode(s, loop, pool, policy, warm) for s in episode_specs[:actors]])
    ledger = EpisodeLedger()
    for spec in episode_specs:
        ledger.admit(spec.sample_id)
    started = time.perf_counter()
    samples = await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in episode_specs])
    elapsed = time.perf_counter() - started
    for actor in pool.actors:
        ray.kill(actor)
    return samples, elapsed, ledger.balance()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--domain", default="triage_emergency")
    parser.add_argument("--pattern", default="^tr_calc_", help="task id regex ('' = all tasks)")
    parser.add_argument("--episodes", type=int, default=96)
    parser.add_argument("--max-turns", type=int, default=5)
    parser.add_argument("--slots", type=int, default=16)
    parser.add_argument("--prompt", choices=["env", "compact"], default="env",
                        help="system prompt style of the agent loop (the tiny configs use compact)")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes per mode; the median is reported")
    parser.add_argument("--json", default=None, help="also write the figures here")
    args = parser.parse_args(argv)
    os.environ.setdefault("HCGYM_EMBEDDINGS", "0")

    import ray

    from actors.agent_loop import AgentLoop, GoldReplayPolicy, RolloutLimits, gold_turn_actions
    from envs import registry
    from learner.train import load_task_refs

    pattern = args.pattern or None
    refs = load_task_refs([args.domain], "train", None, pattern)
    tokenizer = build_tokenizer(args.domain, pattern)
    limits = RolloutLimits(max_turns=args.max_turns)
    tasks = {t.id: t for t in registry.get_tasks(args.domain, "train")}
    policy = GoldReplayPolicy(tokenizer, {r.task_id: gold_turn_actions(tasks[r.task_id], args.max_turns) for r in refs})
    loop = AgentLoop(tokenizer, limits, args.prompt)
    episode_specs = specs(refs, args.episodes)

    asyncio.run(plain_loop(loop, policy, episode_specs[:4], args.max_turns))  # warm-up (imports, first env)
    times = []
    for _ in range(args.repeats):
        started = time.perf_counter()
        plain = asyncio.run(plain_loop(loop, policy, episode_specs, args.max_turns))
        times.append(time.perf_counter() - started)
    plain_s = statistics.median(times)
    results = {"domain": args.domain, "pattern": pattern, "episodes": args.episodes, "cpus": os.cpu_count(),
               "prompt": args.prompt,
               "turns_mean": statistics.mean(len(s.turns) for s in plain),
               "tokens_mean": statistics.mean(len(s.input_ids) for s in plain),
               "plain": {"wall_s": plain_s, "episodes_per_s": args.episodes / plain_s}}
    from envs._runtime import init_ray  # a local cluster on 127.0.0.1 only

    init_ray(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        for actors in (1, 2):
            runs = [asyncio.run(ray_pool(loop, policy, episode_specs, args.max_turns, actors, args.slots,
                                         {"HCGYM_EMBEDDINGS": "0"})) for _ in range(args.repeats)]
            samples, _, balance = runs[0]
            elapsed = statistics.median(r[1] for r in runs)
            same = all(a.input_ids == b.input_ids and a.reward == b.reward for a, b in zip(samples, plain))
            results[f"ray_{actors}_actors"] = {
                "wall_s": elapsed, "episodes_per_s": args.episodes / elapsed,
                "overhead_ms_per_episode": 1000 * (elapsed - plain_s) / args.episodes,
                "same_trajectories_as_plain_loop": same, "ledger": balance,
            }
    finally:
        ray.shutdown()
    print(f"rollout benchmark: {args.episodes} gold-replay episodes of {args.domain} ({pattern}, {args.prompt} prompt), "
          f"{results['turns_mean']:.2f} turns, {results['tokens_mean']:.0f} tokens each, {os.cpu_count()} CPUs")
    print(f"  plain loop         {plain_s:7.2f} s  {results['plain']['episodes_per_s']:7.2f} episodes/s")
    for actors in (1, 2):
        r = results[f"ray_{actors}_actors"]
        print(f"  Ray, {actors} env actor(s) {r['wall_s']:7.2f} s  {r['episodes_per_s']:7.2f} episodes/s  "
              f"overhead {r['overhead_ms_per_episode']:+.1f} ms/episode  identical={r['same_trajectories_as_plain_loop']}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
