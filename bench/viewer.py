"""How fast `hcgym view` opens and filters a large run, against reading it the notebook way.

Builds a run folder of `--episodes` training episodes (default 100,000: `--steps` Parquet files of
episodes each) from real gold-replay episodes of a domain (the real env executes the gold tool
calls; the trainer's own `write_samples` writes them, token columns and episode records included),
copied across steps with distinct sample ids and rewards so the files have a real run's size.
Then measures:

* open: the viewer's episode index of the whole run (projected reads of the scalar columns) plus
  the first page of the table, as the Episodes page asks for it;
* filters: the median of several table queries (domain, reward range, error kind, task substring,
  correctness), each returning one page with the match count;
* baseline (the peer): what a notebook does without the viewer, `pq.read_table` of every file with
  all columns and a Python filter over the rows, timed once on `--baseline-files` files spread over
  the run and scaled to the whole run (all of it as Python objects would not fit in memory).

Targets from the issue: open < 2 s, filter < 300 ms on 100K episodes.

    python bench/viewer.py [--episodes 100000] [--steps 1000] [--domain triage_emergency]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def build_run(root: Path, domain: str, episodes: int, steps: int) -> Path:
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from actors.agent_loop import (
        AgentLoop,
        EpisodeSpec,
        GoldReplayPolicy,
        LocalEnv,
        RolloutLimits,
        gold_turn_actions,
    )
    from bench.rollout import build_tokenizer
    from envs import registry
    from learner.metrics import write_samples

    per_step = max(1, episodes // steps)
    tasks = registry.get_tasks(domain, "train")[:per_step]
    tokenizer = build_tokenizer(domain, None)
    limits = RolloutLimits(max_turns=5)
    policy = GoldReplayPolicy(tokenizer, {t.id: gold_turn_actions(t, limits.max_turns) for t in tasks})
    loop = AgentLoop(tokenizer, limits, "compact")

    async def run_all():
        env = LocalEnv(limits.max_turns)
        return [await loop.run(EpisodeSpec(sample_id=f"{t.id}:0:{i}", task_id=t.id, domain=domain, group_id=f"g{i}",
                                           seed=i), env, policy) for i, t in enumerate(tasks)]

    samples = asyncio.run(run_all())
    while len(samples) < per_step:
        samples = samples + samples[: per_step - len(samples)]
    template = root / "template.parquet"
    write_samples(samples, template, step=1)
    base = pq.read_table(template)
    run = root / "run"
    (run / "trajectories").mkdir(parents=True)
    n = base.num_rows
    for step in range(1, steps + 1):
        # distinct ids and spread rewards per step, as a real run's steps would have
        rewards = pc.multiply(pc.add(base["reward"], (step % 7) / 10), 0.6)
        table = (base.set_column(base.schema.get_field_index("sample_id"), "sample_id",
                                 pa.array([f"{s}:{step}" for s in base["sample_id"].to_pylist()]))
                 .set_column(base.schema.get_field_index("step"), "step", pa.array([step] * n, pa.int32()))
                 .set_column(base.schema.get_field_index("reward"), "reward", rewards))
        pq.write_table(table, run / "trajectories" / f"step_{step:06d}.parquet")
    (run / "metrics.jsonl").write_text("".join(f'{{"step": {s}, "accuracy": 0.5}}\n' for s in range(1, steps + 1)))
    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=100_000)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--domain", default="triage_emergency")
    parser.add_argument("--baseline-files", type=int, default=50, help="files the baseline reads (then scaled)")
    parser.add_argument("--keep", default=None, help="build the run folder here and keep it")
    args = parser.parse_args(argv)
    os.environ.setdefault("HCGYM_EMBEDDINGS", "0")

    import pyarrow.parquet as pq

    from viewer.data import EpisodeQuery, RunSource

    root = Path(args.keep or tempfile.mkdtemp(prefix="bench_viewer_"))
    started = time.perf_counter()
    run = build_run(root, args.domain, args.episodes, args.steps)
    files = sorted((run / "trajectories").glob("*.parquet"))
    size_mb = sum(p.stat().st_size for p in files) / 1e6
    print(f"run: {len(files)} files, {size_mb:.0f} MB, built in {time.perf_counter() - started:.0f} s")

    started = time.perf_counter()
    source = RunSource(id="s0", path=run)
    first = source.episodes(EpisodeQuery())
    open_s = time.perf_counter() - started
    total = first["total"]
    sample_task = first["rows"][0]["task_id"]
    queries = {
        "domain": EpisodeQuery(domain=args.domain),
        "reward range": EpisodeQuery(reward_min=0.3, reward_max=0.6),
        "error kind": EpisodeQuery(error_kind="tool_error"),
        "task substring": EpisodeQuery(task=sample_task[:6]),
        "correct + step": EpisodeQuery(correct=True, step=500),
    }
    filter_s = {}
    for name, query in queries.items():
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            source.episodes(query)
            times.append(time.perf_counter() - t0)
        filter_s[name] = statistics.median(times)

    # The baseline on a sample of the files, scaled to the run: reading all 100K episodes' every
    # column into Python objects needs more memory than a laptop has.
    sample = files[:: max(1, len(files) // args.baseline_files)][: args.baseline_files]
    t0 = time.perf_counter()
    rows = [r for p in sample for r in pq.read_table(p).to_pylist()]
    matched = [r for r in rows if 0.3 <= r["reward"] <= 0.6]
    baseline_s = (time.perf_counter() - t0) * len(files) / len(sample)
    print(f"baseline sample: {len(rows):,} episodes read, {len(matched):,} in the reward range")

    print(f"episodes: {total:,}")
    print(f"open (index + first page):       {open_s:6.2f} s   (target < 2 s)")
    for name, seconds in filter_s.items():
        print(f"filter {name:<24} {seconds * 1000:6.1f} ms  (target < 300 ms)")
    print(f"baseline: read every column and filter in Python: {baseline_s:6.2f} s for the run "
          f"(measured on {len(sample)} of {len(files)} files, scaled)")
    print(f"ratio: viewer open is {baseline_s / open_s:.1f}x faster than the baseline; "
          f"a filter {baseline_s / max(filter_s.values()):.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
