"""Reward throughput: episodes scored per second by `score_episode` with the default grader.

Target: >= 2,000 multiple-choice episodes/s on one core. Baseline measured in the same run: a
naive reference-style grader (the gold letter as a substring of the answer, plus a flat format
check), which is what the reference implementation did; the script also reports how often that
baseline mis-grades the same episodes (hedges, lists, "Vitamin D" read as D).

Episodes are realistic multi-turn trajectories: a `think` call, a knowledge search with a JSON
result, and `submit_answer` with a reasoning string; answers vary between a committed letter, a
wrong letter, a hedge, an option list and an option text. Management and free-text episodes
(embeddings off) are reported for information.

Run: OMP_NUM_THREADS=1 python bench/rewards.py [--episodes 2000] [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("HCGYM_EMBEDDINGS", "0")  # the default grader never needs them for MC; keep FT deterministic
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs.core.task import Task  # noqa: E402
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord  # noqa: E402
from envs.rewards import StaticSafetyContext, score_episode, score_episodes  # noqa: E402

OPTION_SETS = [
    {"A": "Vitamin A", "B": "Vitamin C", "C": "Iron", "D": "Vitamin D"},
    {"A": "Rotator cuff tear", "B": "Pneumothorax due to pleural injury", "C": "Trapezius paresis",
     "D": "Traumatic carotid aneurysm", "E": "Brachial plexus injury"},
    {"A": "Hepatitis A", "B": "Hepatitis B", "C": "Hepatitis C", "D": "Hepatitis E"},
    {"A": "Bradykinin increase; angiotensin II decrease", "B": "Renin decrease; angiotensin I increase",
     "C": "Aldosterone increase; bradykinin decrease", "D": "Renin decrease; angiotensin II increase"},
]
_CALL = '<tool_call>{"name": "%s", "arguments": %s}</tool_call>'


def _call(name: str, args: dict, result: str, submit: bool = False) -> ToolCallRecord:
    return ToolCallRecord(name=name, arguments=args, result=result, format="hermes", submit=submit, tool_type="read")


def mc_episode(i: int) -> tuple[Trajectory, Task, bool]:
    """One multiple-choice episode and whether its answer is truly correct."""
    options = OPTION_SETS[i % len(OPTION_SETS)]
    letters = sorted(options)
    gold = letters[(i * 7) % len(letters)]
    wrong = letters[(letters.index(gold) + 1) % len(letters)]
    kind = i % 5
    answer, correct = {
        0: (f"Answer: {gold}", True),
        1: (gold, True),
        2: (f"Answer: {wrong}", False),
        3: (f"{wrong} or {gold}", False),            # a hedge: the naive grader credits it
        4: (", ".join(letters), False),              # every option: the naive grader credits it
    }[kind]
    task = Task(id=f"bench-mc-{i % 997}", ticket=f"Question {i}: which option is right?", options=options,
                correct_answer=gold, domain="medical_qa")
    search_result = json.dumps([{"doc_id": f"pubmed_{1000 + k}", "title": options[gold], "snippet": "..." * 20}
                                for k in range(3)])
    turns = [
        TurnRecord(index=0, action=_CALL % ("think", '{"thought": "..."}'), message="Let me reason about the options.",
                   action_format="hermes", tool_calls=[_call("think", {"thought": f"Consider {options[gold]} first."}, "Thought recorded.")]),
        TurnRecord(index=1, action=_CALL % ("search_pubmed", '{"query": "..."}'), action_format="hermes",
                   tool_calls=[_call("search_pubmed", {"query": options[gold], "max_results": 3}, search_result)]),
        TurnRecord(index=2, action=_CALL % ("submit_answer", "{...}"), action_format="hermes",
                   tool_calls=[_call("submit_answer", {"answer": answer, "reasoning": f"The evidence supports {options[gold]}."},
                                     f"Answer submitted: {answer}", submit=True)]),
    ]
    traj = Trajectory(task_id=task.id, domain="medical_qa", turns=turns, submitted_answer=answer, terminated=True,
                      first_observation=task.ticket)
    return traj, task, correct


def management_episode(i: int) -> tuple[Trajectory, Task, StaticSafetyContext]:
    drug = ("amoxicillin", "metformin", "ibuprofen", "lisinopril")[i % 4]
    task = Task(id=f"bench-mgmt-{i % 97}", ticket="Sinusitis in a 54-year-old; allergic to penicillin.", patient_id="P1",
                correct_answer=drug, answer_type="exact", domain="clinical_diagnosis",
                evaluation_criteria={"actions": [{"name": "get_patient_info", "arguments": {"patient_id": "P1"}},
                                                 {"name": "prescribe_medication", "arguments": {"patient_id": "P1", "drug": drug},
                                                  "compare_args": ["drug"]}]})
    calls = [
        _call("get_patient_info", {"patient_id": "P1"}, '{"id": "P1", "allergies": ["penicillin"]}'),
        _call("check_drug_interactions", {"patient_id": "P1"}, "no interactions"),
        _call("prescribe_medication", {"patient_id": "P1", "drug": drug, "dose_mg": 500, "route": "oral"}, "ok"),
        _call("schedule_follow_up", {"patient_id": "P1", "days": 14}, "booked"),
        _call("submit_answer", {"answer": drug, "reasoning": f"Start {drug} 500 mg; follow up in two weeks."}, "ok", submit=True),
    ]
    turns = [TurnRecord(index=k, action=_CALL % (c.name, "{}"), action_format="hermes", tool_calls=[c]) for k, c in enumerate(calls)]
    traj = Trajectory(task_id=task.id, domain="clinical_diagnosis", turns=turns, submitted_answer=drug, terminated=True)
    context = StaticSafetyContext(allergies={"P1": ["penicillin"]}, medications={"P1": ["warfarin"]})
    return traj, task, context


def free_text_episode(i: int) -> tuple[Trajectory, Task]:
    task = Task(id=f"bench-ft-{i % 97}", ticket="What is the most likely result of a penetrating wound above the clavicle?",
                correct_answer="Pneumothorax due to pleural injury", answer_type="free_text")
    answer = ("A pneumothorax from injury to the pleura", "Rotator cuff tear", "Collapsed lung")[i % 3]
    call = _call("submit_answer", {"answer": answer}, "ok", submit=True)
    traj = Trajectory(task_id=task.id, domain="medical_qa", submitted_answer=answer, terminated=True,
                      turns=[TurnRecord(index=0, action="...", action_format="hermes", tool_calls=[call])])
    return traj, task


def naive_reference_grade(traj: Trajectory, task: Task) -> tuple[float, float]:
    """(accuracy, total) the reference's way: the gold letter anywhere in the answer."""
    text = traj.submitted_answer or (traj.turns[-1].message if traj.turns else "")
    accuracy = 1.0 if task.correct_answer and task.correct_answer in text else 0.0
    fmt = 1.0 if traj.turns and traj.turns[-1].tool_calls else 0.0
    return accuracy, (0.25 * accuracy + 0.20 + 0.10 * fmt + 0.10) / 0.65


def rate(fn, items, repeats: int) -> tuple[float, float, list[float]]:
    """(median episodes per CPU-second of this process, median episodes per wall second, CPU rates).

    CPU time (`time.process_time`) is what "on one core" means on a shared machine: the
    process is single-threaded, so episodes / CPU-second is its one-core throughput even when
    other jobs compete for the cores (wall-clock rates are reported too).
    """
    fn(items[: min(50, len(items))])  # warm-up (regex compilation, caches)
    cpu_rates, wall_rates = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        fn(items)
        cpu_rates.append(len(items) / max(time.process_time() - cpu, 1e-9))
        wall_rates.append(len(items) / (time.perf_counter() - wall))
    return statistics.median(cpu_rates), statistics.median(wall_rates), cpu_rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--embeddings", action="store_true",
                        help="also time free-text episodes graded with the offline embedding model")
    args = parser.parse_args()

    mc = [mc_episode(i) for i in range(args.episodes)]
    ours, ours_wall, ours_all = rate(lambda xs: [score_episode(t, k) for t, k, _ in xs], mc, args.repeats)
    base, base_wall, base_all = rate(lambda xs: [naive_reference_grade(t, k) for t, k, _ in xs], mc, args.repeats)
    ours_wrong = sum(score_episode(t, k).is_correct != c for t, k, c in mc) / len(mc)
    naive_wrong = sum((naive_reference_grade(t, k)[0] == 1.0) != c for t, k, c in mc) / len(mc)

    mgmt = [management_episode(i) for i in range(max(200, args.episodes // 4))]
    mgmt_rate, mgmt_wall, _ = rate(lambda xs: [score_episode(t, k, context=c) for t, k, c in xs], mgmt, args.repeats)
    ft = [free_text_episode(i) for i in range(max(200, args.episodes // 4))]
    ft_rate, ft_wall, _ = rate(lambda xs: [score_episode(t, k) for t, k in xs], ft, args.repeats)
    sem_rate = sem_batch_rate = None
    if args.embeddings:
        from envs.rewards import similarity

        os.environ["HCGYM_EMBEDDINGS"] = "1"
        similarity.set_embedder(None)
        start = time.perf_counter()
        loaded = similarity.get_embedder() is not None
        load_s = time.perf_counter() - start
        print(f"embedding model: {similarity.embedding_status()} in {load_s:.1f} s")
        if loaded:
            varied = [(t.model_copy(update={"submitted_answer": f"{t.submitted_answer} (variant {i})"}), k)
                      for i, (t, k) in enumerate(ft)]  # distinct texts: no embedding-cache hits
            sem_rate, sem_wall, _ = rate(lambda xs: [score_episode(t, k) for t, k in xs], varied, 1)
            batched = [(t.model_copy(update={"submitted_answer": f"{t.submitted_answer} (batched {i})"}), k)
                       for i, (t, k) in enumerate(ft)]
            sem_batch_rate, sem_batch_wall, _ = rate(lambda xs: score_episodes(xs), batched, 1)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")

    result = {
        "episodes": args.episodes, "repeats": args.repeats, "threads": os.environ.get("OMP_NUM_THREADS"),
        "load_average_1min": round(load, 2), "cpu_count": os.cpu_count(),
        "mc_episodes_per_cpu_s": round(ours), "mc_episodes_per_wall_s": round(ours_wall),
        "mc_cpu_rates": [round(r) for r in ours_all],
        "baseline": "naive reference-style substring grader",
        "baseline_episodes_per_cpu_s": round(base), "baseline_episodes_per_wall_s": round(base_wall),
        "ratio_vs_baseline": round(ours / base, 4),
        "misgraded_ours": round(ours_wrong, 4), "misgraded_baseline": round(naive_wrong, 4),
        "management_episodes_per_cpu_s": round(mgmt_rate), "free_text_overlap_episodes_per_cpu_s": round(ft_rate),
        "free_text_semantic_episodes_per_cpu_s": None if sem_rate is None else round(sem_rate),
        "free_text_semantic_batched_episodes_per_cpu_s": None if sem_batch_rate is None else round(sem_batch_rate),
        "target_mc_episodes_per_s": 2000, "pass": ours >= 2000,
    }
    print(f"machine: {os.cpu_count()} cores, load average {load:.2f}; rates are per CPU-second of this single-threaded process"
          " (wall-clock in brackets)")
    print(f"score_episode, multiple choice (3-turn episodes): {ours:,.0f} episodes/s [{ours_wall:,.0f}] "
          f"(median of {args.repeats} x {args.episodes})")
    print(f"baseline ({result['baseline']}): {base:,.0f} episodes/s [{base_wall:,.0f}]; ratio ours/baseline = {ours / base:.4f}")
    print(f"mis-graded correctness: ours {ours_wrong:.1%}, baseline {naive_wrong:.1%} (hedges, option lists)")
    print(f"patient management (5 calls, safety context): {mgmt_rate:,.0f} episodes/s [{mgmt_wall:,.0f}]")
    print(f"free text (token overlap, embeddings off): {ft_rate:,.0f} episodes/s [{ft_wall:,.0f}]")
    if sem_rate is not None:
        print(f"free text (overlap + MiniLM embeddings, distinct answers): {sem_rate:,.0f} episodes/s [{sem_wall:,.0f}]"
              f"; batched with score_episodes: {sem_batch_rate:,.0f} episodes/s [{sem_batch_wall:,.0f}]")
    print(f"target >= 2,000 MC episodes/s on one core: {'PASS' if ours >= 2000 else 'FAIL'}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
