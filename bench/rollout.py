"""Rollout throughput with the scripted gold-replay policy: a plain in-process loop vs the Ray
env-actor pool with 1 and 2 actors, each with one actor call per reset / step / release
(unbatched), with the calls waiting on an actor batched into one call (batched, the `EnvPool`
default) and batched with the answers streamed back as they finish (streamed), on the same episodes.

The policy is `GoldReplayPolicy` (no model), so the figures measure the rollout machinery itself:
environment steps, tool execution, grading, TITO tokenization and, for Ray, the actor round trips.
Every mode runs `--repeats` times, interleaved round by round in one process (the starting mode
rotates), and the median is reported; actor start-up is excluded (the two pools are started and
warmed up first and reused). The overhead figure is the Ray pipeline's wall time per episode minus
the plain loop's; every pass of every Ray mode must give the plain loop's trajectories token for token.

    python bench/rollout.py [--domain triage_emergency] [--episodes 96] [--pattern ^tr_calc_] [--prompt compact]
        [--repeats 5] [--json out.json]
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
    from modeling.model import load_tokenizer, train_tokenizer
    from learner.sft import task_corpus

    out = Path(tempfile.mkdtemp(prefix="bench_rollout_tok_"))
    train_tokenizer(task_corpus([domain], "train", pattern), 2048, out, max_stdlib_files=40)
    return load_tokenizer(out)


#: Queries of the search-heavy workload (`--searches`): clinical phrases, rotated per task; the
#: vague ones (only common words: "left", "unspecified", "injury") are the costly searches (1-14 ms).
SEARCH_QUERIES = (
    "left right bilateral unspecified", "other specified injury of unspecified part",
    "unspecified injury of left lower leg", "chronic disease of other site",
    "type 2 diabetes with chronic kidney disease", "acute myocardial infarction", "community acquired pneumonia",
    "sepsis due to urinary tract infection", "chronic obstructive pulmonary disease with acute exacerbation",
    "iron deficiency anemia", "major depressive disorder recurrent", "atrial fibrillation",
    "acute kidney injury", "hypertensive heart disease with heart failure", "cellulitis of lower limb",
    "pulmonary embolism", "migraine without aura", "gastrointestinal hemorrhage", "hypothyroidism",
    "asthma with status asthmaticus",
)


#: The costly queries only (`--queries vague`): every search scans many candidate codes, so an
#: episode's env work is large against the driver's tokenization of its small observations.
VAGUE_QUERIES = SEARCH_QUERIES[:4]


def with_searches(actions: list[str], searches: int, index: int, queries: tuple[str, ...] = SEARCH_QUERIES) -> list[str]:
    """The gold actions with `searches` ICD-10 searches (one result each, so the observation stays
    small and the cost is the search itself) made in the first turn before its gold calls."""
    calls = ["<tool_call>" + json.dumps({"name": "search_icd10", "arguments": {
        "query": queries[(index + i) % len(queries)], "limit": 1}}) + "</tool_call>"
        for i in range(searches)]
    return ["\n".join(calls + actions[:1])] + actions[1:]


def specs(refs, n):
    from actors.agent_loop import EpisodeSpec

    return [EpisodeSpec(sample_id=f"{refs[i % len(refs)].task_id}:{i}:{i}", task_id=refs[i % len(refs)].task_id,
                        domain=refs[i % len(refs)].domain, split=refs[i % len(refs)].split, group_id=f"b{i}", seed=i)
            for i in range(n)]


async def plain_loop(loop, policy, episode_specs, max_turns):
    from actors.agent_loop import LocalEnv

    env = LocalEnv(max_turns)
    return [await loop.run(spec, env, policy) for spec in episode_specs]


async def pool_pass(pool, loop, policy, episode_specs):
    """One timed pass of every episode over `pool` (all admitted at once, as the trainer does)."""
    from actors.env_actor import EpisodeLedger, run_episode

    ledger = EpisodeLedger()
    for spec in episode_specs:
        ledger.admit(spec.sample_id)
    actors_before = [p["cpu_s"] for p in await pool.ready()]
    cpu_started, started = time.process_time(), time.perf_counter()
    samples = await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in episode_specs])
    wall, driver_cpu = time.perf_counter() - started, time.process_time() - cpu_started
    actors_cpu = [p["cpu_s"] - b for p, b in zip(await pool.ready(), actors_before)]
    return samples, wall, ledger.balance(), {"driver": driver_cpu, "actors": actors_cpu}


#: `ray_<actors>_<calls>`: unbatched = one actor call per reset / step / release; batched = the
#: calls waiting on an actor in one call, answered at once (the `EnvPool` default); streamed =
#: batched, answers streamed back in chunks as they finish (`--stream-after-ms`).
MODES = ("plain", "ray_1_unbatched", "ray_1_batched", "ray_1_streamed",
         "ray_2_unbatched", "ray_2_batched", "ray_2_streamed")
CALLS = {"unbatched": {"batch_calls": False}, "batched": {"batch_calls": True, "stream_after_s": None},
         "streamed": {"batch_calls": True, "stream_after_s": 0.002}}


async def measure(loop, policy, episode_specs, args) -> dict[str, list]:
    """Every mode `args.repeats` times, interleaved (the start mode rotates each round), so load from
    other processes on a shared machine falls on all modes alike. Returns mode -> [(samples, s, ledger)]."""
    from actors.env_actor import EnvPool, EpisodeLedger, run_episode

    pools = {}
    for actors in (1, 2):
        pool = EnvPool(actors, args.slots, args.max_turns, env_vars={"HCGYM_EMBEDDINGS": "0"})
        await pool.ready()
        # Warm-up: a few episodes per actor, so actor start and first imports are not timed.
        warm = EpisodeLedger()
        for spec in episode_specs[: 2 * actors]:
            warm.admit(spec.sample_id)
        await asyncio.gather(*[run_episode(s, loop, pool, policy, warm) for s in episode_specs[: 2 * actors]])
        pools[actors] = pool
    await plain_loop(loop, policy, episode_specs[:4], args.max_turns)  # warm-up (imports, first env)
    runs: dict[str, list] = {mode: [] for mode in MODES}
    for round_index in range(args.repeats):
        for mode in MODES[round_index % len(MODES):] + MODES[:round_index % len(MODES)]:
            if mode == "plain":
                cpu_started, started = time.process_time(), time.perf_counter()
                samples = await plain_loop(loop, policy, episode_specs, args.max_turns)
                runs[mode].append((samples, time.perf_counter() - started, None,
                                   {"driver": time.process_time() - cpu_started, "actors": []}))
                continue
            _, actors, calls = mode.split("_")
            pool = pools[int(actors)]
            for name, value in CALLS[calls].items():
                setattr(pool, name, value)
            if calls == "streamed":
                pool.stream_after_s = args.stream_after_ms / 1000
            runs[mode].append(await pool_pass(pool, loop, policy, episode_specs))
    stats = {actors: await pool.ready() for actors, pool in pools.items()}
    return runs, stats


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--domain", default="triage_emergency")
    parser.add_argument("--pattern", default="^tr_calc_", help="task id regex ('' = all tasks)")
    parser.add_argument("--episodes", type=int, default=96)
    parser.add_argument("--max-turns", type=int, default=5)
    parser.add_argument("--slots", type=int, default=16)
    parser.add_argument("--prompt", choices=["env", "compact"], default="env",
                        help="system prompt style of the agent loop (the tiny configs use compact)")
    parser.add_argument("--repeats", type=int, default=5, help="timed passes per mode; the median is reported")
    parser.add_argument("--queries", choices=["mixed", "vague"], default="mixed",
                        help="--searches' queries: all clinical phrases (mixed) or only the costly vague ones")
    parser.add_argument("--searches", type=int, default=0,
                        help="medical_qa only: ICD-10 searches each episode makes in its first turn besides the "
                             "gold calls (a knowledge-search-heavy workload: env work dominates)")
    parser.add_argument("--stream-after-ms", type=float, default=2.0,
                        help="streamed mode: the actor sends a chunk of answers per this much work (EnvPool.stream_after_s)")
    parser.add_argument("--json", default=None, help="also write the figures here")
    args = parser.parse_args(argv)
    if args.searches and args.domain != "medical_qa":
        parser.error(f"--searches uses medical_qa's search_icd10 tool; got --domain {args.domain}")
    if not 0 <= args.searches < 32:
        parser.error(f"--searches must be 0-31 (an action may make at most 32 tool calls), got {args.searches}")
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
    policy = GoldReplayPolicy(tokenizer, {r.task_id: with_searches(gold_turn_actions(tasks[r.task_id], args.max_turns),
                                                                   args.searches, index,
                                                                   VAGUE_QUERIES if args.queries == "vague" else SEARCH_QUERIES)
                                          for index, r in enumerate(refs)})
    loop = AgentLoop(tokenizer, limits, args.prompt)
    episode_specs = specs(refs, args.episodes)

    from envs._runtime import init_ray  # a local cluster on 127.0.0.1 only

    init_ray(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        runs, pings = asyncio.run(measure(loop, policy, episode_specs, args))
    finally:
        ray.shutdown()
    plain = runs["plain"][0][0]
    wall = {mode: statistics.median(r[1] for r in runs[mode]) for mode in MODES}
    # CPU-seconds a pass (medians): the driver process (agent loop, tokenization, Ray client) and
    # each env actor; with the wall time they say whether a pool's actors were busy or waiting.
    cpu = {mode: {"driver": statistics.median(r[3]["driver"] for r in runs[mode]),
                  "actors": [statistics.median(r[3]["actors"][i] for r in runs[mode])
                             for i in range(len(runs[mode][0][3]["actors"]))]} for mode in MODES}
    results = {"domain": args.domain, "pattern": pattern, "episodes": args.episodes, "cpus": os.cpu_count(),
               "prompt": args.prompt, "searches": args.searches, "queries": args.queries, "stream_after_ms": args.stream_after_ms, "repeats": args.repeats, "load_average": os.getloadavg(),
               "turns_mean": statistics.mean(len(s.turns) for s in plain),
               "tokens_mean": statistics.mean(len(s.input_ids) for s in plain),
               "plain": {"wall_s": wall["plain"], "episodes_per_s": args.episodes / wall["plain"],
                         "passes_s": [r[1] for r in runs["plain"]], "cpu_s": cpu["plain"]}}
    for mode in MODES[1:]:
        same = all(a.input_ids == b.input_ids and a.reward == b.reward and a.episode == b.episode
                   for run in runs[mode] for a, b in zip(run[0], plain))
        results[mode] = {
            "wall_s": wall[mode], "episodes_per_s": args.episodes / wall[mode], "passes_s": [r[1] for r in runs[mode]],
            "vs_plain": wall["plain"] / wall[mode],
            "overhead_ms_per_episode": 1000 * (wall[mode] - wall["plain"]) / args.episodes,
            "same_trajectories_as_plain_loop": same, "ledger": runs[mode][0][2], "cpu_s": cpu[mode],
        }
    results["vs_unbatched"] = {f"{c}, {a} actor(s)": wall[f"ray_{a}_unbatched"] / wall[f"ray_{a}_{c}"]
                               for a in (1, 2) for c in ("batched", "streamed")}
    results["two_vs_one_actor"] = {c: wall[f"ray_1_{c}"] / wall[f"ray_2_{c}"] for c in CALLS}
    results["calls_per_batch"] = {a: sum(p["batched_calls"] for p in ps) / max(1, sum(p["batches"] for p in ps))
                                  for a, ps in pings.items()}
    print(f"rollout benchmark: {args.episodes} gold-replay episodes of {args.domain} ({pattern}, {args.prompt} prompt), "
          f"{args.searches} extra searches ({args.queries} queries), {results['turns_mean']:.2f} turns, {results['tokens_mean']:.0f} tokens each, {os.cpu_count()} CPUs, "
          f"medians of {args.repeats} interleaved passes, load average {results['load_average'][0]:.1f}")
    print(f"  plain loop                   {wall['plain']:7.3f} s  {results['plain']['episodes_per_s']:7.1f} episodes/s  "
          f"CPU-s driver {cpu['plain']['driver']:.2f}")
    for mode in MODES[1:]:
        r = results[mode]
        print(f"  Ray, {mode[4]} actor(s), {mode[6:]:9s} {r['wall_s']:7.3f} s  {r['episodes_per_s']:7.1f} episodes/s  "
              f"{r['vs_plain']:.2f}x plain  overhead {r['overhead_ms_per_episode']:+.1f} ms/episode  "
              f"identical={r['same_trajectories_as_plain_loop']}  CPU-s driver {cpu[mode]['driver']:.2f}, actors "
              + " + ".join(f"{c:.2f}" for c in cpu[mode]["actors"]))
    print("  vs unbatched: " + ", ".join(f"{k} {v:.2f}x" for k, v in results["vs_unbatched"].items())
          + "; 2 / 1 actors: " + ", ".join(f"{c} {v:.2f}x" for c, v in results["two_vs_one_actor"].items())
          + "; calls per batch: " + ", ".join(f"{a} actor(s) {v:.1f}" for a, v in results["calls_per_batch"].items()))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
