"""`hcgym eval compare DIR_A DIR_B [--output DIR]`: paired differences of two results folders.

Items are paired on (benchmark, task_id, seed): only episodes both folders ran count. Per
benchmark (and over all shared items):
  * the primary metric of each side and the difference A - B with a paired-bootstrap 95% CI
    (items resampled jointly; an item's value is its mean over the shared seeds),
  * for accuracy-type metrics, the exact McNemar test on the per-episode correctness pairs
    (discordant counts and the two-sided p-value).
Written as markdown (`comparison.md`, which with --output also holds each side's metrics with
their own CIs side by side, plotted in `conditions.png`) and JSON (`comparison.json`), and printed.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from evals.metrics import PRIMARY, SECONDARY, load_tasks_for, read_results, row_values
from evals.report import (
    comparison_table,
    fmt_pct,
    label_of,
    metric_kinds,
    plot_benchmarks,
    read_spec,
    summarise_results,
)
from evals.stats import mcnemar_exact, paired_bootstrap_ci
from evals.suites import benchmark_specs

BINARY_METRICS = {"accuracy"}


def _paired(rows_a: list[dict[str, Any]], rows_b: list[dict[str, Any]], kind: str, tasks: dict[str, Any],
            metric: str | None = None
            ) -> tuple[list[tuple[str, int]], dict[tuple[str, int], float], dict[tuple[str, int], float]]:
    """Episode values of `metric` (default: the benchmark kind's primary metric) keyed by (task, seed)."""
    metric = metric or PRIMARY[kind]

    def values(rows):
        out = {}
        for r in rows:
            value = row_values(r, kind, tasks.get(r["task_id"])).get(metric)
            if value is not None:
                out[(r["task_id"], int(r["seed"]))] = value
        return out

    a, b = values(rows_a), values(rows_b)
    shared = sorted(set(a) & set(b))
    return shared, a, b


def _item_means(keys: list[tuple[str, int]], a: dict, b: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per-item means over seeds of both sides (items are the resampling unit)."""
    items: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for key in keys:
        items[key[0]].append((a[key], b[key]))
    return (np.array([np.mean([p[0] for p in pairs]) for pairs in items.values()]),
            np.array([np.mean([p[1] for p in pairs]) for pairs in items.values()]))


def compare_rows(rows_a: list[dict[str, Any]], rows_b: list[dict[str, Any]], kinds: dict[str, str],
                 tasks: dict[str, Any] | None = None, *, seed: int = 0, n_resamples: int = 10_000,
                 order: list[str] | None = None) -> dict[str, Any]:
    """Per-benchmark paired comparison (see module doc); benchmarks with no shared items are listed apart.

    `order`: benchmark names in the order to report them (the suite's); the rest follow sorted. The
    pooled "all shared items" line covers the accuracy-type benchmarks only: averaging accuracy with
    ROUGE-L or an action score would mean nothing.
    """
    tasks = tasks or {}
    by_a, by_b = defaultdict(list), defaultdict(list)
    for r in rows_a:
        by_a[r["benchmark"]].append(r)
    for r in rows_b:
        by_b[r["benchmark"]].append(r)
    results, unshared = [], []
    pooled_a, pooled_b, pooled_ca, pooled_cb = [], [], [], []
    names = set(by_a) | set(by_b)
    for bench in [b for b in order or [] if b in names] + sorted(names - set(order or [])):
        kind = kinds.get(bench, "accuracy")
        shared, a, b = _paired(by_a.get(bench, []), by_b.get(bench, []), kind, tasks)
        if not shared:
            unshared.append(bench)
            continue
        item_a, item_b = _item_means(shared, a, b)
        diff = paired_bootstrap_ci(item_a, item_b, seed=seed, n_resamples=n_resamples)
        entry = {"benchmark": bench, "metric": PRIMARY[kind], "items": len(item_a), "episodes": len(shared),
                 "a": float(item_a.mean()), "b": float(item_b.mean()), "difference": diff.as_dict()}
        # The benchmark's other metrics (e.g. the 5D reward of gym tasks), paired the same way.
        entry["secondary"] = []
        for metric in SECONDARY.get(kind, []):
            keys, sa, sb = _paired(by_a.get(bench, []), by_b.get(bench, []), kind, tasks, metric)
            if keys:
                ma, mb = _item_means(keys, sa, sb)
                entry["secondary"].append({
                    "benchmark": bench, "metric": metric, "items": len(ma), "episodes": len(keys),
                    "a": float(ma.mean()), "b": float(mb.mean()),
                    "difference": paired_bootstrap_ci(ma, mb, seed=seed, n_resamples=n_resamples).as_dict()})
        if PRIMARY[kind] in BINARY_METRICS:
            ca = np.array([a[k] >= 0.5 for k in shared])
            cb = np.array([b[k] >= 0.5 for k in shared])
            test = mcnemar_exact(ca, cb)
            entry["mcnemar"] = {"a_only": test.a_only, "b_only": test.b_only, "both": test.both,
                                "neither": test.neither, "p_value": test.p_value}
            pooled_ca.extend(ca)
            pooled_cb.extend(cb)
            pooled_a.extend(item_a)
            pooled_b.extend(item_b)
        results.append(entry)
    overall = None
    if pooled_a:
        diff = paired_bootstrap_ci(pooled_a, pooled_b, seed=seed, n_resamples=n_resamples)
        overall = {"items": len(pooled_a), "a": float(np.mean(pooled_a)), "b": float(np.mean(pooled_b)),
                   "difference": diff.as_dict()}
        if pooled_ca:
            test = mcnemar_exact(pooled_ca, pooled_cb)
            overall["mcnemar"] = {"a_only": test.a_only, "b_only": test.b_only, "both": test.both,
                                  "neither": test.neither, "p_value": test.p_value}
    return {"benchmarks": results, "overall": overall, "unshared": unshared}


def _signed_pct(value: float) -> str:
    return f"{100 * value:+.1f}"


def to_markdown(comparison: dict[str, Any], label_a: str, label_b: str) -> str:
    lines = [f"# Paired comparison: A = {label_a}, B = {label_b}", "",
             ("Items paired on (benchmark, task, seed); differences A - B in percentage points with paired-bootstrap "
              "95% CIs; McNemar: exact two-sided test on discordant episodes (A-only / B-only correct)."), "",
             "| Benchmark | Metric | Items | A | B | A - B [95% CI] | A-only / B-only | McNemar p |",
             "|---|---|---:|---:|---:|---|---|---:|"]
    rows = [row for e in comparison["benchmarks"] for row in (e, *e.get("secondary", []))]
    if comparison["overall"]:
        rows.append({"benchmark": "**all shared items**", "metric": "accuracy", **comparison["overall"]})
    for e in rows:
        d = e["difference"]
        mc = e.get("mcnemar")
        lines.append(f"| {e['benchmark']} | {e['metric']} | {e['items']} | {fmt_pct(e['a'])} | {fmt_pct(e['b'])} | "
                     f"{_signed_pct(d['estimate'])} [{_signed_pct(d['low'])}, {_signed_pct(d['high'])}] | "
                     + (f"{mc['a_only']} / {mc['b_only']} | {mc['p_value']:.4g} |" if mc else "- | - |"))
    if comparison["unshared"]:
        lines += ["", "Benchmarks without shared items (not compared): " + ", ".join(comparison["unshared"])]
    return "\n".join(lines) + "\n"


def compare_dirs(dir_a: str | Path, dir_b: str | Path, *, seed: int = 0, n_resamples: int = 10_000
                 ) -> tuple[dict[str, Any], str]:
    dir_a, dir_b = Path(dir_a), Path(dir_b)
    rows_a, rows_b = read_results(dir_a), read_results(dir_b)
    specs = benchmark_specs(read_spec(dir_a).get("suite")) or benchmark_specs(read_spec(dir_b).get("suite"))
    kinds = metric_kinds(rows_a + rows_b, specs)
    tasks = load_tasks_for(rows_a + rows_b, kinds) if "long_form" in kinds.values() else {}
    comparison = compare_rows(rows_a, rows_b, kinds, tasks, seed=seed, n_resamples=n_resamples, order=list(specs))
    label_a, label_b = label_of(dir_a, rows_a), label_of(dir_b, rows_b)
    comparison.update(a=str(dir_a), b=str(dir_b), label_a=label_a, label_b=label_b)
    return comparison, to_markdown(comparison, label_a, label_b)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="hcgym eval compare",
                                     description="paired differences of two results folders on their shared items")
    parser.add_argument("dir_a", help="results folder A (results.parquet)")
    parser.add_argument("dir_b", help="results folder B")
    parser.add_argument("--output", help="folder to write comparison.md and comparison.json into")
    parser.add_argument("--resamples", type=int, default=10_000, help="bootstrap resamples (default 10000)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    args = parser.parse_args(argv)
    for name in (args.dir_a, args.dir_b):
        if not (Path(name) / "results.parquet").is_file():
            print(f"error: {name}: not a results folder (no results.parquet)", file=sys.stderr)
            return 2
    comparison, markdown = compare_dirs(args.dir_a, args.dir_b, seed=args.seed, n_resamples=args.resamples)
    if args.output:
        out = Path(args.output)
        out.mkdir(parents=True, exist_ok=True)
        # each side's own metric with its (unpaired) CI, side by side, as a table and grouped bars
        summaries = [summarise_results(d, seed=args.seed, n_resamples=args.resamples) for d in (args.dir_a, args.dir_b)]
        plot_benchmarks(summaries, out / "conditions.png", "condition by condition")
        markdown += ("\n## Condition by condition\n\n" + "\n".join(comparison_table(summaries))
                     + "\n\n![conditions](conditions.png)\n")
        (out / "comparison.md").write_text(markdown, encoding="utf-8")
        (out / "comparison.json").write_text(json.dumps(comparison, indent=2), encoding="utf-8")
    print(markdown, end="")
    if not comparison["benchmarks"]:
        print("error: the two folders share no (benchmark, task, seed) items", file=sys.stderr)
        return 1
    return 0


__all__ = ["compare_dirs", "compare_rows", "main", "to_markdown"]
