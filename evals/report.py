"""Reports of a results folder: `report.md` with tables like the paper's, plots, `summary.json`.

`write_report(results_dir)` reads `results.parquet` (+ `eval.json` for the suite, policy and
condition) and writes, into the same folder:

* `report.md`: per benchmark (the paper's Table "Benchmark results" layout: category, benchmark,
  metric in % with its bootstrap 95% CI, n items; a benchmark selected by a metadata filter, such as
  MMLU-Med's six subjects, also per value of it), per domain and per task type (accuracy and mean
  reward with CIs), episode statistics (end reasons, safety-violation rates by severity, turns,
  tool calls, tokens, error kinds), and the suite's benchmarks that have no rows with the import
  command that brings each;
* `benchmarks.png`: the primary metric per benchmark as bars with CI whiskers;
* `summary.json`: every number of the report, machine-readable.

`write_report(results_dir, others=[dir, ...])` adds a condition-by-condition table and
`conditions.png` (grouped bars, one group per benchmark, one bar per results folder).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from evals.metrics import PRIMARY, episode_stats, group_rows, load_tasks_for, read_results, summarise
from evals.suites import BenchmarkSpec, benchmark_specs, import_commands

PERCENT_METRICS = {"accuracy", "closed_accuracy", "open_accuracy", "action_score", "reward", "rouge_l",
                   "hallucination", "comprehensiveness"}


def read_spec(results_dir: Path) -> dict[str, Any]:
    path = results_dir / "eval.json"
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON at line {exc.lineno}: {exc.msg}") from None


def fmt_pct(value: float) -> str:
    return f"{100 * value:.1f}"


def fmt_interval(summary: dict[str, Any]) -> str:
    return f"{fmt_pct(summary['estimate'])} [{fmt_pct(summary['low'])}, {fmt_pct(summary['high'])}]"


def label_of(results_dir: Path, rows: list[dict[str, Any]]) -> str:
    spec = read_spec(results_dir)
    policy = spec.get("policy_id") or (rows[0]["policy_id"] if rows else "?")
    condition = spec.get("condition") or (rows[0]["condition"] if rows else "?")
    return f"{policy} ({condition})"


def metric_kinds(rows: list[dict[str, Any]], specs: dict[str, BenchmarkSpec]) -> dict[str, str]:
    """Benchmark -> metric kind: the suite's, else `gym` for the gym's own suites, else accuracy."""
    out = {}
    for bench in {r["benchmark"] for r in rows}:
        if bench in specs:
            out[bench] = specs[bench].metric
        else:
            out[bench] = "gym" if bench.startswith(("gym_", "val_")) else "accuracy"
    return out


def summarise_results(results_dir: str | Path, *, seed: int = 0, n_resamples: int = 10_000) -> dict[str, Any]:
    """Every number a report prints, from one results folder."""
    results_dir = Path(results_dir)
    rows = read_results(results_dir)
    spec = read_spec(results_dir)
    specs = benchmark_specs(spec.get("suite"))
    kinds = metric_kinds(rows, specs)
    # a benchmark selected by a metadata filter (MMLU-Med's six subjects) is also broken down by it
    breakdown = {name: next(iter(s.select.metadata)) for name, s in specs.items() if name in kinds and s.select.metadata
                 and kinds[name] != "long_form"}
    needs_tasks = "long_form" in kinds.values() or breakdown
    tasks = load_tasks_for(rows, kinds, also=breakdown) if needs_tasks else {}
    order = [name for name in specs if name in kinds] + sorted(b for b in kinds if b not in specs)
    by_bench = group_rows(rows, lambda r: r["benchmark"])
    benchmarks = []
    for name in order:
        bench_spec = specs.get(name)
        metrics = summarise(by_bench[name], kinds[name], tasks, seed=seed, n_resamples=n_resamples)
        parts = []
        if name in breakdown:
            key = breakdown[name]
            found = [r for r in by_bench[name] if r["task_id"] in tasks]
            by_value = group_rows(found, lambda r, key=key: str(tasks[r["task_id"]].metadata.get(key)))
            for value, group in sorted(by_value.items()):
                part = summarise(group, kinds[name], tasks, seed=seed, n_resamples=n_resamples)
                parts.append({"by": key, "value": value, "metrics": [m.as_dict() for m in part]})
        benchmarks.append({
            "benchmark": name, "title": bench_spec.title if bench_spec else name,
            "category": bench_spec.category if bench_spec else "", "metric_kind": kinds[name],
            "primary": PRIMARY[kinds[name]], "metrics": [m.as_dict() for m in metrics], "parts": parts,
        })

    def by(field: str) -> list[dict[str, Any]]:
        out = []
        for value, group in sorted(group_rows(rows, lambda r: r[field]).items()):
            metrics = summarise(group, "gym", seed=seed, n_resamples=n_resamples)
            out.append({field: value, "metrics": [m.as_dict() for m in metrics]})
        return out

    missing = [{"benchmark": name, "title": s.title, "commands": import_commands(s)}
               for name, s in specs.items() if name not in kinds]
    return {"label": label_of(results_dir, rows), "spec": spec, "episodes": len(rows), "benchmarks": benchmarks,
            "domains": by("domain"), "task_types": by("task_type"), "episode_stats": episode_stats(rows),
            "missing": missing}


def _metric(entry: dict[str, Any], name: str) -> dict[str, Any] | None:
    return next((m for m in entry["metrics"] if m["metric"] == name), None)


def _benchmark_table(summary: dict[str, Any]) -> list[str]:
    lines = ["| Category | Benchmark | Metric | Value [95% CI] | n | Other metrics [95% CI] |",
             "|---|---|---|---|---:|---|"]
    for bench in summary["benchmarks"]:
        primary = _metric(bench, bench["primary"])
        others = "; ".join(f"{m['metric']} {fmt_interval(m)} (n={m['n']})" for m in bench["metrics"]
                           if m["metric"] != bench["primary"])
        lines.append(f"| {bench['category']} | {bench['title']} | {bench['primary']} | {fmt_interval(primary)} | "
                     f"{primary['n']} | {others or '-'} |")
        for part in bench.get("parts", []):
            value = _metric(part, bench["primary"])
            lines.append(f"| | &nbsp;&nbsp;{part['by']}: {part['value']} | {bench['primary']} | {fmt_interval(value)} | "
                         f"{value['n']} | |")
    return lines


def _group_table(entries: list[dict[str, Any]], field: str) -> list[str]:
    lines = [f"| {field.replace('_', ' ').title()} | Accuracy [95% CI] | Reward [95% CI] | n |", "|---|---|---|---:|"]
    for entry in entries:
        acc, reward = _metric(entry, "accuracy"), _metric(entry, "reward")
        n = max(m["n"] for m in entry["metrics"])
        lines.append(f"| {entry[field]} | {fmt_interval(acc) if acc else '-'} | {fmt_interval(reward)} | {n} |")
    return lines


def _episode_section(stats: dict[str, Any]) -> list[str]:
    lines = ["| Statistic | Per episode |", "|---|---:|"]
    for key, title in (("turns_mean", "turns"), ("tool_calls_mean", "tool calls"), ("prompt_tokens_mean", "prompt tokens"),
                       ("completion_tokens_mean", "completion tokens"), ("latency_s_mean", "latency (s)")):
        lines.append(f"| {title} | {stats[key]:.2f} |")
    lines.append(f"| any safety violation (rate) | {fmt_pct(stats['safety']['any_rate'])}% |")
    for level, s in stats["safety"]["by_severity"].items():
        lines.append(f"| safety violations, severity {level} (rate / count) | {fmt_pct(s['rate'])}% / {s['per_episode']:.3f} |")
    if stats["cost_usd_total"] is not None:
        lines.append(f"| cost (USD, total) | {stats['cost_usd_total']:.4f} |")
    lines += ["", "End reasons: " + ", ".join(f"{k} {v}" for k, v in stats["end_reasons"].items())]
    if stats["episode_error_kinds"]:
        lines.append("Episode errors: " + ", ".join(f"{k} {v}" for k, v in stats["episode_error_kinds"].items()))
    if stats["error_kinds"]:
        lines.append("Tool/parse error kinds (per episode): "
                     + ", ".join(f"{k} {v / stats['episodes']:.3f}" for k, v in stats["error_kinds"].items()))
    return lines


def plot_benchmarks(summaries: list[dict[str, Any]], path: Path, title: str) -> Path:
    """Grouped bars of each benchmark's primary metric (one bar per results folder) with CI whiskers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(dict.fromkeys(b["benchmark"] for s in summaries for b in s["benchmarks"]))
    width = 0.8 / max(1, len(summaries))
    fig, ax = plt.subplots(figsize=(max(5.0, 0.8 * len(names) * max(1, len(summaries)) + 2), 4))
    for i, summary in enumerate(summaries):
        lookup = {b["benchmark"]: _metric(b, b["primary"]) for b in summary["benchmarks"]}
        xs = np.arange(len(names)) + (i - (len(summaries) - 1) / 2) * width
        est = np.array([100 * lookup[n]["estimate"] if n in lookup else np.nan for n in names])
        low = np.array([100 * lookup[n]["low"] if n in lookup else np.nan for n in names])
        high = np.array([100 * lookup[n]["high"] if n in lookup else np.nan for n in names])
        ax.bar(xs, est, width, label=summary["label"], yerr=[est - low, high - est], capsize=3)
    ax.set_xticks(np.arange(len(names)))
    ax.set_xticklabels(names, rotation=45, ha="right")
    ax.set_ylabel("primary metric (%) with 95% CI")
    ax.set_ylim(0, 100)
    ax.set_title(title)
    if len(summaries) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def comparison_table(summaries: list[dict[str, Any]]) -> list[str]:
    names = list(dict.fromkeys(b["benchmark"] for s in summaries for b in s["benchmarks"]))
    lines = ["| Benchmark | " + " | ".join(s["label"] for s in summaries) + " |",
             "|---|" + "---|" * len(summaries)]
    for name in names:
        cells = []
        for summary in summaries:
            bench = next((b for b in summary["benchmarks"] if b["benchmark"] == name), None)
            cells.append(fmt_interval(_metric(bench, bench["primary"])) if bench else "-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def write_report(results_dir: str | Path, others: list[str | Path] | None = None, *, seed: int = 0,
                 n_resamples: int = 10_000) -> Path:
    """Write report.md, benchmarks.png (+ conditions.png with `others`) and summary.json; returns report.md."""
    results_dir = Path(results_dir)
    summary = summarise_results(results_dir, seed=seed, n_resamples=n_resamples)
    spec = summary["spec"]
    lines = [f"# Evaluation report: {summary['label']}", ""]
    if spec:
        lines.append(f"Policy `{spec.get('policy', '?')}`, suite `{spec.get('suite', '?')}`, condition "
                     f"`{spec.get('condition', '?')}`, seeds {spec.get('seeds', '?')}, {summary['episodes']} episodes.")
    else:
        lines.append(f"{summary['episodes']} episodes (no eval.json in this folder).")
    lines += ["", (f"Values are percentages with percentile-bootstrap 95% confidence intervals ({n_resamples:,} "
                   "resamples of items; an item's value is its mean over seeds); n counts items."), "",
              "## Benchmark results", "", *_benchmark_table(summary), "",
              "![benchmarks](benchmarks.png)", "",
              "## By domain", "", *_group_table(summary["domains"], "domain"), "",
              "## By task type", "", *_group_table(summary["task_types"], "task_type"), "",
              "## Episodes", "", *_episode_section(summary["episode_stats"]), ""]
    if summary["missing"]:
        lines += ["## Benchmarks of the suite without results", ""]
        for miss in summary["missing"]:
            lines.append(f"- **{miss['title']}** (`{miss['benchmark']}`): bring it with")
            lines.extend(f"    `{c}`" for c in miss["commands"])
        lines.append("")
    plot_benchmarks([summary], results_dir / "benchmarks.png", summary["label"])
    extra = [summarise_results(o, seed=seed, n_resamples=n_resamples) for o in others or []]
    if extra:
        lines += ["## Condition by condition", "", *comparison_table([summary, *extra]), "",
                  "![conditions](conditions.png)", ""]
        plot_benchmarks([summary, *extra], results_dir / "conditions.png", "condition by condition")
    (results_dir / "summary.json").write_text(json.dumps({"report": summary, "others": extra}, indent=2),
                                              encoding="utf-8")
    report = results_dir / "report.md"
    report.write_text("\n".join(lines), encoding="utf-8")
    return report


__all__ = ["comparison_table", "fmt_interval", "plot_benchmarks", "read_spec", "summarise_results", "write_report"]
