"""Calibration of the rule grader for natural-language assertions, over every task that has them.

For each task with NL assertions in every domain, three episodes are graded against the task's own
assertions with `RuleGrader` (the default grader without an LLM judge):

* **gold replay**: the task's expected actions run in a fresh environment, then the gold answer
  submitted (`envs.validate.gold_replay`, the replay `hcgym tasks validate` uses);
* **other task's replay** (a wrong episode): the gold replay of another task of the same domain with
  a different gold answer and different assertions (not the same workflow on another patient),
  graded against this task's assertions: a well-formed, competent-looking episode about the wrong
  patient or question;
* **gold answer, no tools**: only `submit_answer` with the gold answer.

It prints, per domain and overall, the distribution (min, 10th percentile, median, mean) of the
assertion score for each kind, the share of gold replays at or above 0.9, the gap between the gold
replay and the wrong episode of the same task, and the lowest-scoring gold-replay criteria.
Baseline measured in the same run: the same grader with tool observations left out of the
evidence (only the agent's text, its answer and its calls), the largest single change of the
calibration. The grader of commit 749e5f4, before the calibration, is compared in docs/rewards.md
and docs/benchmarks.md ("Gold replays against their own NL assertions").

Run: OMP_NUM_THREADS=1 python bench/assertion_calibration.py [--domains a,b] [--limit N] [--json out.json]
     (HCGYM_EMBEDDINGS=0 grades by keywords only)
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import registry  # noqa: E402
from envs.core.task import Task  # noqa: E402
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord  # noqa: E402
from envs.validate import gold_replay  # noqa: E402
from envs.rewards.assertions import RuleGrader, grade_assertions  # noqa: E402
from envs.rewards.view import EpisodeView  # noqa: E402

KINDS = ("gold_replay", "other_task_replay", "gold_answer_no_tools")


def answer_only(task: Task) -> Trajectory:
    answer = task.correct_answer or ""
    call = ToolCallRecord(name="submit_answer", arguments={"answer": answer}, result=f"Answer submitted: {answer}",
                          format="hermes", submit=True)
    return Trajectory(task_id=task.id, domain=task.domain or "", submitted_answer=answer, terminated=True,
                      turns=[TurnRecord(index=0, action="<tool_call>...</tool_call>", action_format="hermes",
                                        tool_calls=[call])])


def nl_only(task: Task) -> Task:
    """The task with its NL assertions only (the rubric is graded elsewhere)."""
    criteria = task.evaluation_criteria.model_copy(update={"rubric": []})
    return task.model_copy(update={"evaluation_criteria": criteria})


def grade(trajectory: Trajectory, task: Task, grader: RuleGrader) -> tuple[float, list]:
    outcome = grade_assertions(EpisodeView(trajectory, nl_only(task)), grader)
    return (outcome.score if outcome.score is not None else 0.0), outcome.nl


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]


def summary(values: list[float]) -> dict[str, float]:
    return {"n": len(values), "min": round(min(values), 3), "p10": round(percentile(values, 0.10), 3),
            "median": round(statistics.median(values), 3), "mean": round(statistics.mean(values), 3)}


def run(domains: list[str], limit: int | None) -> dict:
    rows: list[dict] = []
    replays: dict[str, list[tuple[Task, Trajectory]]] = {}
    started = time.perf_counter()
    unavailable: dict[str, str] = {}
    for domain in domains:
        try:
            tasks = [t for t in registry.get_tasks(domain) if t.evaluation_criteria.nl_assertions]
            replays[domain] = [(t, gold_replay(t, domain)[0]) for t in (tasks[:limit] if limit else tasks)]
        except Exception as exc:  # a domain that cannot load here is reported, the others still measured
            unavailable[domain] = f"{type(exc).__name__}: {exc}"[:200]
            replays.pop(domain, None)
    replay_s = time.perf_counter() - started
    graders = {"calibrated": RuleGrader(), "baseline_no_observations": RuleGrader(use_observations=False)}
    started = time.perf_counter()
    for domain, pairs in replays.items():
        for i, (task, trajectory) in enumerate(pairs):
            # a wrong episode does another job: a different gold answer AND different criteria (the
            # same workflow replayed on another patient, as ehr_management's are, meets patient-agnostic
            # criteria by doing what they ask: it is not a wrong answer to them)
            criteria = set(task.evaluation_criteria.nl_assertions)
            following = (pairs[(i + k) % len(pairs)] for k in range(1, len(pairs)))
            other = next((p for p in following if p[0].correct_answer != task.correct_answer
                          and set(p[0].evaluation_criteria.nl_assertions) != criteria), None)
            episodes = {"gold_replay": trajectory, "gold_answer_no_tools": answer_only(task)}
            if other is not None:
                episodes["other_task_replay"] = other[1]
            row = {"domain": domain, "task": task.id}
            for name, grader in graders.items():
                for kind, episode in episodes.items():
                    score, results = grade(episode, task, grader)
                    row[f"{name}/{kind}"] = round(score, 4)
                    if kind == "gold_replay" and name == "calibrated":
                        row["gold_criteria"] = [(r.text, r.score, r.reason) for r in results]
            rows.append(row)
    grade_s = time.perf_counter() - started
    return {"rows": rows, "replay_s": round(replay_s, 1), "grade_s": round(grade_s, 1), "unavailable": unavailable}


def report(result: dict) -> dict:
    rows = result["rows"]
    out: dict = {"episodes": len(rows), "replay_s": result["replay_s"], "grade_s": result["grade_s"], "grader": {},
                 "unavailable_domains": result["unavailable"]}
    for name in ("calibrated", "baseline_no_observations"):
        section: dict = {}
        for scope in ["all", *dict.fromkeys(r["domain"] for r in rows)]:
            chosen = [r for r in rows if scope == "all" or r["domain"] == scope]
            entry = {kind: summary([r[f"{name}/{kind}"] for r in chosen if f"{name}/{kind}" in r]) for kind in KINDS
                     if any(f"{name}/{kind}" in r for r in chosen)}
            gold = [r[f"{name}/gold_replay"] for r in chosen]
            entry["gold_at_least_0.9"] = f"{sum(g >= 0.9 for g in gold)}/{len(gold)}"
            gaps = [r[f"{name}/gold_replay"] - r[f"{name}/other_task_replay"] for r in chosen if f"{name}/other_task_replay" in r]
            entry["gap_gold_minus_other"] = summary(gaps) if gaps else None
            section[scope] = entry
        out["grader"][name] = section
    # criteria whose content the gold solution never produces: under a third of their keywords
    # anywhere in the replay (calls, results, answer) and no sentence semantically close (< 0.5)
    absent: dict[str, list[int]] = {}
    for r in rows:
        counts = absent.setdefault(r["domain"], [0, 0])
        for _, score, why in r["gold_criteria"]:
            counts[1] += 1
            recall = float(re.search(r"keyword recall ([0-9.]+)", why).group(1))
            semantic = re.search(r"semantic ([0-9.]+)", why)
            if recall < 0.34 and (semantic is None or float(semantic.group(1)) < 0.5):
                counts[0] += 1
    out["gold_criteria_absent_from_replay"] = {d: f"{a}/{n}" for d, (a, n) in absent.items()}
    out["gold_criteria_absent_total"] = f"{sum(a for a, _ in absent.values())}/{sum(n for _, n in absent.values())}"
    low = sorted(((c[1], r["task"], c[0], c[2]) for r in rows for c in r["gold_criteria"] if c[1] is not None and c[1] < 0.9))
    out["lowest_gold_criteria"] = [{"score": s, "task": t, "criterion": c, "reason": why} for s, t, c, why in low[:25]]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--domains", default=",".join(registry.list_domains()))
    parser.add_argument("--limit", type=int, default=None, help="tasks per domain (default: all)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    from envs.rewards.similarity import embedding_status, get_embedder

    get_embedder()
    result = run([d for d in args.domains.split(",") if d], args.limit)
    out = report(result)
    out["embeddings"] = embedding_status()
    print(f"embeddings: {out['embeddings']}; {out['episodes']} tasks with NL assertions; "
          f"replays {out['replay_s']} s, grading {out['grade_s']} s")
    for domain, why in out["unavailable_domains"].items():
        print(f"domain {domain} not measured: {why}")
    for name, section in out["grader"].items():
        print(f"\n== {name}")
        print(f"{'scope':<20} {'kind':<22} {'n':>4} {'min':>6} {'p10':>6} {'median':>7} {'mean':>6}")
        for scope, entry in section.items():
            for kind in KINDS:
                if kind in entry:
                    s = entry[kind]
                    print(f"{scope:<20} {kind:<22} {s['n']:>4} {s['min']:>6.3f} {s['p10']:>6.3f} {s['median']:>7.3f} {s['mean']:>6.3f}")
            gap = entry["gap_gold_minus_other"]
            print(f"{scope:<20} gold >= 0.9: {entry['gold_at_least_0.9']}; gold - other: "
                  + (f"min {gap['min']:.3f} median {gap['median']:.3f}" if gap else "n/a"))
    print(f"\ngold-replay criteria whose content the replay never produces: {out['gold_criteria_absent_total']} "
          + ", ".join(f"{d} {v}" for d, v in out["gold_criteria_absent_from_replay"].items()))
    print("\nlowest gold-replay criteria (calibrated):")
    for item in out["lowest_gold_criteria"]:
        print(f"  {item['score']:.2f} {item['task']}: {item['criterion'][:110]} ({item['reason']})")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()
