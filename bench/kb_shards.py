"""Sharded vs single bm25 index: what sharding costs at query time, and that it changes nothing.

    python bench/kb_shards.py                            # 200,000 passages, 1 / 4 / 16 shards
    python bench/kb_shards.py --n-passages 50000 --shards 1,8

The corpus and queries are `bench/kb.py`'s seeded generator (60-250 words a passage). Every
passage is analysed once (as the KB build does: title, newline, content) and fed to the single
`BM25Builder` and to one `ShardedBM25Builder` per shard count in the same pass; each builder's
`add` and `save` time is measured on its own. Then the indexes are queried with
`KnowledgeBase`'s free-text path (query analysis, term selection, kernel, top 10), interleaved in
blocks of 50 queries, single-threaded: p50 / p99 and q/s of the ranking. Every query's top 10
must be identical (ids, order and float32 scores) across all of them, or the script exits 1.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def _bench_kb():
    spec = importlib.util.spec_from_file_location("bench_kb", ROOT / "bench" / "kb.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n-passages", type=int, default=200_000)
    ap.add_argument("--shards", default="1,4,16", help="shard counts to compare with the single index")
    ap.add_argument("--n-queries", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workdir", default=os.environ.get("HCGYM_BENCH_DIR", "/tmp/hcgym-bench-kb"))
    args = ap.parse_args(argv)

    from kb_service.analysis import MAX_QUERY_TERMS, analyze, plan_query
    from kb_service.engines import BM25Builder, BM25Searcher
    from kb_service.shards import ShardedBM25Builder, ShardedBM25Searcher

    work = Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    bkb = _bench_kb()
    corpus, queries = bkb.make_corpus(work, args.n_passages, args.n_queries, args.seed)
    counts = [int(s) for s in args.shards.split(",")]
    out = Path(tempfile.mkdtemp(prefix="kb-shards-", dir=work))
    names = ["single"] + [f"{c} shards" for c in counts]
    builders = {"single": BM25Builder()}
    for c in counts:
        builders[f"{c} shards"] = ShardedBM25Builder(out / f"raw-{c}", shard_docs=math.ceil(args.n_passages / c))
    add_s = dict.fromkeys(names, 0.0)
    t_an = 0.0
    for p in bkb.iter_corpus(corpus):
        t = time.perf_counter()
        toks = analyze(f"{p['title']}\n{p['content']}" if p.get("title") else p["content"])
        t_an += time.perf_counter() - t
        for name, b in builders.items():
            t = time.perf_counter()
            b.add(toks)
            add_s[name] += time.perf_counter() - t
    save_s, info = {}, {}
    for name, b in builders.items():
        t = time.perf_counter()
        info[name] = b.save(out / name.replace(" ", "-"))
        save_s[name] = time.perf_counter() - t
    del builders
    searchers = {"single": BM25Searcher(out / "single")}
    for c in counts:
        searchers[f"{c} shards"] = ShardedBM25Searcher(out / f"{c}-shards")
    for s in searchers.values():
        s.warmup()

    plans = [plan_query(q).terms for q in queries]
    lat = {n: [] for n in names}
    results = {n: [] for n in names}
    for start in range(0, len(plans), 50):
        for name in names:
            s = searchers[name]
            for terms in plans[start:start + 50]:
                t = time.perf_counter()
                docs, scores = s.search(s.term_ids(terms, MAX_QUERY_TERMS), 10)
                lat[name].append(time.perf_counter() - t)
                results[name].append((docs.tolist(), scores.tolist()))
    same = all(results[n] == results["single"] for n in names)
    for name in names[1:]:
        diff = [i for i, (a, b) in enumerate(zip(results["single"], results[name])) if a != b]
        if diff:
            i = diff[0]
            print(f"[bench] {name}: {len(diff)} queries differ from the single index; first: {queries[i]!r}\n"
                  f"  single {results['single'][i]}\n  {name} {results[name][i]}", flush=True)

    def size(p: Path) -> int:
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())

    rows = []
    print(f"\n{args.n_passages:,} passages, {len(queries)} queries, analysis {t_an:.1f}s (shared), "
          f"load average {os.getloadavg()[0]:.1f}; identical top 10 everywhere: {same}\n")
    print("| index | add | save | on disk | p50 / p99 ms | q/s |")
    print("|---|---|---|---|---|---|")
    for name in names:
        a = np.array(lat[name]) * 1000
        row = {"index": name, "add_s": round(add_s[name], 1), "save_s": round(save_s[name], 1),
               "bytes": size(out / name.replace(" ", "-")), "p50_ms": round(float(np.percentile(a, 50)), 3),
               "p99_ms": round(float(np.percentile(a, 99)), 3), "qps": round(len(a) / (a.sum() / 1000), 1)}
        rows.append(row)
        print(f"| {name} | {row['add_s']} s | {row['save_s']} s | {row['bytes'] / 1e6:.0f} MB | "
              f"{row['p50_ms']} / {row['p99_ms']} | {row['qps']} |")
    (work / f"shards-{args.n_passages}.json").write_text(json.dumps({"rows": rows, "identical": same,
                                                                       "analysis_s": t_an}, indent=2))
    import shutil

    shutil.rmtree(out, ignore_errors=True)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
