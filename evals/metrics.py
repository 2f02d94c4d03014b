"""Per-benchmark metrics computed from result rows (never inside the runner).

Rows are `evals.types.ResultRow`s as dicts (what `read_results` returns from `results.parquet`).
Every metric is a mean of per-episode values, so each has a bootstrap CI over items
(`evals.stats`). With several seeds, an item's value is its mean over seeds first: the bootstrap
resamples items (tasks), the unit that is independent.

Metrics by benchmark kind (the paper's Appendix "Benchmark Suite"):
  accuracy          accuracy = correct episodes / episodes (no answer, an endpoint error or a turn
                    limit counts as wrong: the denominator is every episode run)
  vqa_accuracy      accuracy, plus closed (yes/no) and open accuracy over the task types
                    `vqa_closed` / `vqa_open`
  action_coverage   EHR "action score": the reward's `process` component (expected tool-call
                    coverage), plus the mean reward
  long_form         ROUGE-L F1 against the reference answer, hallucination and comprehensiveness
                    (OLAPH's definitions: comprehensiveness = share of the task's must-have
                    statements the answer states; hallucination = share of its must-have and
                    nice-to-have statements the answer contradicts), graded by keyword rules
                    built from the reward's text helpers (no model, so the numbers reproduce)
  gym               accuracy (the env's `is_correct`) and mean reward
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from envs.rewards.similarity import grading_tokens
from envs.rewards.text import clip01, has_negation, sentences, tokens
from evals.stats import Interval, bootstrap_ci

MET_THRESHOLD = 0.5  # the rule grader's "met" threshold (envs.rewards.assertions.MET_THRESHOLD)
PRIMARY = {"accuracy": "accuracy", "vqa_accuracy": "accuracy", "action_coverage": "action_score",
           "long_form": "rouge_l", "gym": "accuracy"}
SECONDARY = {"accuracy": [], "vqa_accuracy": ["closed_accuracy", "open_accuracy"],
             "action_coverage": ["reward"], "long_form": ["hallucination", "comprehensiveness"],
             "gym": ["reward"]}
MAP_FIELDS = ("reward_components", "safety_violations", "error_kinds", "options", "extra")


# -- reading rows ----------------------------------------------------------------------------------
def _as_mapping(value: Any) -> dict[str, Any] | None:
    """Parquet may store a dict as a struct (dict), a map (list of pairs) or a JSON string."""
    if value is None or isinstance(value, dict):
        return value
    if isinstance(value, str):
        loaded = json.loads(value) if value.strip() else {}
        return loaded if isinstance(loaded, dict) else None
    if isinstance(value, (list, tuple)):
        return {str(k): v for k, v in value}
    raise TypeError(f"cannot read {type(value).__name__} as a mapping")


def normalise_row(row: dict[str, Any]) -> dict[str, Any]:
    out = dict(row)
    for field in MAP_FIELDS:
        if field in out:
            out[field] = _as_mapping(out[field])
    for field in ("reward_components", "safety_violations", "error_kinds", "extra"):
        out[field] = out.get(field) or {}
    return out


def read_results(results_dir: str | Path) -> list[dict[str, Any]]:
    """The rows of `results_dir/results.parquet` as dicts (validated by `evals.types.read_results`)."""
    from evals.types import RESULTS_FILE
    from evals.types import read_results as read_rows

    path = Path(results_dir) / RESULTS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no results.parquet in this results folder")
    return [normalise_row(row.model_dump()) for row in read_rows(path)]


# -- long-form graders -----------------------------------------------------------------------------
def lcs_length(a: list[str], b: list[str]) -> int:
    """Length of the longest common subsequence (dynamic programming over one row, O(len(b)) memory)."""
    if not a or not b:
        return 0
    previous = [0] * (len(b) + 1)
    for token in a:
        current = [0]
        for j, other in enumerate(b, start=1):
            current.append(previous[j - 1] + 1 if token == other else max(previous[j], current[j - 1]))
        previous = current
    return previous[-1]


def rouge_l(prediction: str, reference: str) -> float:
    """ROUGE-L F1 (beta = 1) over lower-case word tokens."""
    pred, ref = tokens(prediction or ""), tokens(reference or "")
    lcs = lcs_length(pred, ref)
    if lcs == 0:
        return 0.0
    precision, recall = lcs / len(pred), lcs / len(ref)
    return 2 * precision * recall / (precision + recall)


def _statement_words(statement: str) -> list[str]:
    return list(dict.fromkeys(grading_tokens(statement)))


def _best_sentence(statement: str, answer: str) -> tuple[float, str | None]:
    """The answer sentence covering most of the statement's content words, and that share."""
    words = _statement_words(statement)
    if not words:
        return 0.0, None
    best, best_sentence = 0.0, None
    for sentence in sentences(answer or ""):
        present = set(grading_tokens(sentence))
        share = sum(w in present for w in words) / len(words)
        if share > best:
            best, best_sentence = share, sentence
    return best, best_sentence


def statement_supported(statement: str, answer: str) -> bool:
    """The answer states it: a sentence of the same polarity recalls enough of its content words
    (the rule grader's keyword score clip((recall - 0.2) / 0.6) >= 0.5, i.e. recall >= 0.5)."""
    share, sentence = _best_sentence(statement, answer)
    if sentence is None or has_negation(sentence) != has_negation(statement):
        return False
    return clip01((share - 0.2) / 0.6) >= MET_THRESHOLD


def statement_contradicted(statement: str, answer: str) -> bool:
    """The answer says the opposite: its closest sentence names the same content but flips polarity."""
    share, sentence = _best_sentence(statement, answer)
    if sentence is None:
        return False
    return clip01((share - 0.2) / 0.6) >= MET_THRESHOLD and has_negation(sentence) != has_negation(statement)


def long_form_statements(task: Any) -> tuple[list[str], list[str]]:
    """(must-have, nice-to-have) statements of a MedLFQA task (`envs.converters` rubric tags)."""
    must = [r.criterion for r in task.evaluation_criteria.rubric if "must_have" in r.tags]
    nice = [r.criterion for r in task.evaluation_criteria.rubric if "nice_to_have" in r.tags]
    if not must and not nice:
        must = list(task.evaluation_criteria.nl_assertions)
    return must, nice


def answer_text(row: dict[str, Any]) -> str:
    """The policy's long-form text: `extra` keeps the full text where `answer` is a short extraction."""
    extra = row.get("extra") or {}
    for key in ("long_form_text", "answer_text", "final_text"):
        if isinstance(extra.get(key), str) and extra[key].strip():
            return extra[key]
    return row.get("answer") or ""


# -- per-row values --------------------------------------------------------------------------------
def _correct(row: dict[str, Any]) -> float | None:
    """1/0; an episode that ended without an answer is wrong, an answered one without a gold to
    grade against (correct is None) is left out rather than counted wrong."""
    if row.get("correct") is None:
        return None if row.get("end_reason") in ("answer", "text_answer") else 0.0
    return 1.0 if row["correct"] else 0.0


def row_values(row: dict[str, Any], metric: str, task: Any = None) -> dict[str, float | None]:
    """Each metric of a benchmark kind for one episode; None where it does not apply to this row."""
    if metric in ("accuracy",):
        return {"accuracy": _correct(row)}
    if metric == "vqa_accuracy":
        kind = row.get("task_type")
        return {"accuracy": _correct(row), "closed_accuracy": _correct(row) if kind == "vqa_closed" else None,
                "open_accuracy": _correct(row) if kind == "vqa_open" else None}
    if metric == "action_coverage":
        components = row.get("reward_components") or {}
        return {"action_score": float(components.get("process", 0.0)), "reward": float(row.get("reward") or 0.0)}
    if metric == "gym":
        return {"accuracy": _correct(row), "reward": float(row.get("reward") or 0.0)}
    if metric == "long_form":
        text = answer_text(row)
        values: dict[str, float | None] = {"rouge_l": rouge_l(text, row.get("gold") or ""),
                                           "hallucination": None, "comprehensiveness": None}
        if task is not None:
            must, nice = long_form_statements(task)
            if must:
                values["comprehensiveness"] = float(np.mean([statement_supported(s, text) for s in must]))
            if must or nice:
                values["hallucination"] = float(np.mean([statement_contradicted(s, text) for s in must + nice]))
        return values
    raise ValueError(f"unknown metric {metric!r}; known: {sorted(PRIMARY)}")


# -- aggregation with CIs -------------------------------------------------------------------------
@dataclass(frozen=True)
class MetricSummary:
    """One metric of one group: the estimate with its bootstrap CI over `n` items (episodes in `episodes`)."""

    name: str
    interval: Interval
    episodes: int

    def as_dict(self) -> dict[str, Any]:
        return {"metric": self.name, **self.interval.as_dict(), "episodes": self.episodes}


def item_means(keys: list[str], values: list[float]) -> np.ndarray:
    """One value per item: the mean over that item's episodes (seeds), in first-seen item order."""
    sums: dict[str, list[float]] = defaultdict(list)
    for key, value in zip(keys, values):
        sums[key].append(value)
    return np.array([np.mean(v) for v in sums.values()], dtype=float)


def summarise(rows: list[dict[str, Any]], metric: str, tasks: dict[str, Any] | None = None, *,
              seed: int = 0, n_resamples: int = 10_000) -> list[MetricSummary]:
    """The primary and secondary metrics of a benchmark kind over `rows`, each with a 95% CI."""
    tasks = tasks or {}
    per_metric: dict[str, tuple[list[str], list[float]]] = defaultdict(lambda: ([], []))
    for row in rows:
        for name, value in row_values(row, metric, tasks.get(row["task_id"])).items():
            if value is not None:
                keys, values = per_metric[name]
                keys.append(f"{row['benchmark']}|{row['task_id']}")
                values.append(value)
    out = []
    for name in [PRIMARY[metric], *SECONDARY[metric]]:
        if name not in per_metric:
            continue
        keys, values = per_metric[name]
        interval = bootstrap_ci(item_means(keys, values), seed=seed, n_resamples=n_resamples)
        out.append(MetricSummary(name, interval, len(values)))
    return out


def group_rows(rows: Iterable[dict[str, Any]], key: Callable[[dict[str, Any]], Any]) -> dict[Any, list[dict[str, Any]]]:
    groups: dict[Any, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[key(row)].append(row)
    return dict(groups)


def load_tasks_for(rows: list[dict[str, Any]], metric_of: dict[str, str],
                   also: Iterable[str] = ()) -> dict[str, Any]:
    """Tasks of the long-form rows (their statements live in the task, not the row) and of the
    benchmarks in `also` (e.g. for a breakdown by a task's metadata); {} for the rest. A task that
    no longer exists leaves hallucination/comprehensiveness (or its breakdown) out for its rows."""
    from envs import registry
    from envs.core.domain import imported_tasks_dir
    from envs.core.task import load_tasks

    also = set(also)
    wanted: dict[str, set[str]] = defaultdict(set)
    for row in rows:
        if metric_of.get(row["benchmark"]) == "long_form" or row["benchmark"] in also:
            wanted[row["domain"]].add(row["task_id"])
    found: dict[str, Any] = {}
    for domain, ids in wanted.items():
        if domain not in registry.list_domains():
            continue
        # benchmark tasks are imported ones: read their folder first (it needs no data build, and
        # the registry's task store is loaded once per process, before later imports)
        for path in sorted(imported_tasks_dir(domain).glob("*.json")):
            found.update({t.id: t for t in load_tasks(path, domain=domain) if t.id in ids})
        if ids <= found.keys():
            continue
        try:
            domain_tasks = registry.get_tasks(domain)
        except (OSError, ValueError):  # data not built here (DataFileError is a ValueError): leave them out
            continue
        found.update({t.id: t for t in domain_tasks if t.id in ids})
    return found


# -- episode statistics ----------------------------------------------------------------------------
def episode_stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Safety violations by severity, turns, tool calls, error kinds, end reasons and tokens per episode."""
    n = len(rows)
    if n == 0:
        return {"episodes": 0}
    severities = sorted({str(s) for r in rows for s in r["safety_violations"]}, key=lambda s: (len(s), s))
    safety = {}
    for level in severities:
        counts = np.array([int(r["safety_violations"].get(level, 0)) for r in rows])
        safety[level] = {"episodes_with": int((counts > 0).sum()), "rate": float((counts > 0).mean()),
                         "per_episode": float(counts.mean()), "total": int(counts.sum())}
    any_violation = np.array([sum(int(v) for v in r["safety_violations"].values()) > 0 for r in rows])
    error_kinds: Counter[str] = Counter()
    for r in rows:
        error_kinds.update({k: int(v) for k, v in r["error_kinds"].items()})
    episode_errors = Counter(r["error_kind"] for r in rows if r.get("error_kind"))

    def mean(field: str) -> float:
        return float(np.mean([float(r.get(field) or 0) for r in rows]))

    costs = [r["cost_usd"] for r in rows if r.get("cost_usd") is not None]
    return {
        "episodes": n,
        "safety": {"any_rate": float(any_violation.mean()), "by_severity": safety},
        "turns_mean": mean("turns"), "tool_calls_mean": mean("tool_calls"),
        "prompt_tokens_mean": mean("prompt_tokens"), "completion_tokens_mean": mean("completion_tokens"),
        "latency_s_mean": mean("latency_s"),
        "cost_usd_total": float(sum(costs)) if costs else None,
        "end_reasons": dict(Counter(r["end_reason"] for r in rows).most_common()),
        "episode_error_kinds": dict(episode_errors.most_common()),
        "error_kinds": dict(error_kinds.most_common()),
        "error_kinds_per_episode": {k: v / n for k, v in error_kinds.most_common()},
    }


__all__ = [
    "PRIMARY",
    "SECONDARY",
    "MetricSummary",
    "answer_text",
    "episode_stats",
    "group_rows",
    "item_means",
    "lcs_length",
    "load_tasks_for",
    "long_form_statements",
    "normalise_row",
    "read_results",
    "rouge_l",
    "row_values",
    "statement_contradicted",
    "statement_supported",
    "summarise",
]
