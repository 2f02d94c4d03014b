"""report.md, plots and `hcgym eval compare` from results folders this test writes itself.

Rows go through `evals.types.row_to_record` + pyarrow, the way the runner writes them; every
number checked below is worked out by hand in the comments (or is the same bootstrap call on the
same item values, for the CI bounds).
"""

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from envs.core.domain import imported_tasks_dir
from evals import compare
from evals.metrics import read_results, rouge_l
from evals.report import write_report
from evals.stats import bootstrap_ci
from evals.types import EvalSpec, ResultRow, row_to_record

FIX_BENCHMARKS = Path(__file__).parents[1] / "fixtures" / "benchmarks"


def _row(policy, benchmark, domain, task_id, correct, *, seed=0, task_type="multiple_choice", **extra):
    fields = {"policy_id": policy, "benchmark": benchmark, "domain": domain, "task_id": task_id,
              "task_type": task_type, "condition": "agent", "seed": seed, "end_reason": "answer", "correct": correct,
              "reward": 1.0 if correct else 0.0, "turns": 3, "tool_calls": 2, "prompt_tokens": 100,
              "completion_tokens": 20, "latency_s": 0.5, "trajectory_ref": f"trajectories.parquet#{task_id}-{seed}"}
    fields.update(extra)
    return ResultRow(**fields)


def write_folder(path, rows, policy_id, seeds):
    path.mkdir(parents=True)
    pq.write_table(pa.Table.from_pylist([row_to_record(r) for r in rows]), path / "results.parquet")
    spec = EvalSpec(policy=f"runs/{policy_id}", policy_id=policy_id, suite="paper18", condition="agent", seeds=seeds)
    (path / "eval.json").write_text(spec.model_dump_json(), encoding="utf-8")
    return path


# MedQA, A: seed 0 right on m0-m6; seed 1 right on m0-m6 and m9 -> item means 1 x7, 0.5 (m9), 0 x2 = 75.0%
A_MEDQA = {0: {f"m{i}" for i in range(7)}, 1: {f"m{i}" for i in range(7)} | {"m9"}}
# MedQA, B: right everywhere except m0 in both seeds -> 90.0%
B_MEDQA = {seed: {f"m{i}" for i in range(1, 10)} for seed in (0, 1)}
LIVEQA_GOLD = "Face drooping is a warning sign; call emergency services immediately."
LIVEQA_ANSWER = "Call emergency services right away if face drooping starts."


def medqa_rows(policy, right):
    rows = []
    for seed, ids in right.items():
        for i in range(10):
            task = f"m{i}"
            extra = {}
            if policy == "sft" and seed == 0 and task in ("m0", "m1"):
                extra["safety_violations"] = {"3": 1}
            if policy == "sft" and seed == 0 and task == "m2":
                extra["safety_violations"] = {"5": 1}
            if policy == "sft" and seed == 0 and task == "m8":
                extra.update(end_reason="turn_limit")
            if policy == "sft" and seed == 0 and task == "m9":
                extra.update(end_reason="endpoint_error", error_kind="http_500", turns=1, tool_calls=0)
            rows.append(_row(policy, "medqa", "medical_qa", task, task in ids, seed=seed, **extra))
    return rows


@pytest.fixture
def folders(tmp_path):
    a_rows = medqa_rows("sft", A_MEDQA)
    # VQA-RAD: 4 closed (3 right) and 2 open (1 right) -> 66.7% overall, 75.0% closed, 50.0% open
    a_rows += [_row("sft", "vqa_rad", "visual_diagnosis", f"v{i}", ok, task_type="vqa_closed")
               for i, ok in enumerate([True, True, True, False])]
    a_rows += [_row("sft", "vqa_rad", "visual_diagnosis", f"o{i}", ok, task_type="vqa_open")
               for i, ok in enumerate([True, False])]
    # MIMIC-III: action score = the `process` component: (0.5 + 1.0 + 0.0) / 3 = 50.0%; reward (0.2+0.4+0.6)/3 = 40.0%
    a_rows += [_row("sft", "mimic3", "ehr_management", f"e{i}", None, task_type="mimic3_labs", reward=reward,
                    reward_components={"process": process, "accuracy": 0.0})
               for i, (process, reward) in enumerate([(0.5, 0.2), (1.0, 0.4), (0.0, 0.6)])]
    a_rows.append(_row("sft", "liveqa", "medical_qa", "lf0", None, task_type="long_form", gold=LIVEQA_GOLD,
                       answer="call emergency services", extra={"long_form_text": LIVEQA_ANSWER}))
    b_rows = medqa_rows("rl", B_MEDQA) + [_row("rl", "slake", "visual_diagnosis", "s0", True, task_type="vqa_closed")]
    return (write_folder(tmp_path / "sft", a_rows, "sft", [0, 1]), write_folder(tmp_path / "rl", b_rows, "rl", [0, 1]))


def test_rouge_l_by_hand():
    # pred 9 tokens, ref 10 tokens, LCS "call emergency services" = 3: F1 = 2 (3/9)(3/10) / (3/9 + 3/10) = 0.3158
    assert rouge_l(LIVEQA_ANSWER, LIVEQA_GOLD) == pytest.approx(2 * (3 / 9) * (3 / 10) / (3 / 9 + 3 / 10))
    assert rouge_l("", LIVEQA_GOLD) == 0.0 and rouge_l(LIVEQA_GOLD, LIVEQA_GOLD) == pytest.approx(1.0)


def test_read_results_decodes_the_json_columns(folders):
    rows = read_results(folders[0])
    assert len(rows) == 20 + 6 + 3 + 1
    assert next(r for r in rows if r["benchmark"] == "mimic3")["reward_components"]["process"] == 0.5
    with pytest.raises(FileNotFoundError, match="results.parquet"):
        read_results(folders[0].parent)


def test_report_tables_numbers_and_plots(folders):
    sft, _ = folders
    report = write_report(sft, n_resamples=2000)
    text = report.read_text()
    medqa_ci = bootstrap_ci([1.0] * 7 + [0.5, 0.0, 0.0], n_resamples=2000)
    assert (f"| MC QA | MedQA (USMLE) | accuracy | 75.0 [{100 * medqa_ci.low:.1f}, {100 * medqa_ci.high:.1f}] | 10 |"
            in text)
    assert "| Visual QA | VQA-RAD | accuracy | 66.7 [" in text
    assert "closed_accuracy 75.0 [" in text and "(n=4)" in text and "open_accuracy 50.0 [" in text
    assert "| EHR | MIMIC-III | action_score | 50.0 [" in text and "reward 40.0 [" in text
    assert "| LFQA | LiveQA | rouge_l | 31.6 [31.6, 31.6] | 1 |" in text
    # the paper's order: MedQA before VQA-RAD before MIMIC-III before LiveQA
    assert text.index("MedQA (USMLE)") < text.index("VQA-RAD") < text.index("MIMIC-III") < text.index("| LiveQA")
    # suite benchmarks without rows, with the command that brings them
    assert "**MMLU-Med (6 sub.)** (`mmlu_med`)" in text and "hcgym tasks import --format medmcqa" in text
    # episodes: 30 in all; severity 3 in 2 (6.7%), severity 5 in 1 (3.3%); any violation 3/30 = 10.0%
    assert "| safety violations, severity 3 (rate / count) | 6.7% / 0.067 |" in text
    assert "| safety violations, severity 5 (rate / count) | 3.3% / 0.033 |" in text
    assert "| any safety violation (rate) | 10.0% |" in text
    assert "turn_limit 1" in text and "endpoint_error 1" in text and "Episode errors: http_500 1" in text
    # turns: 29 episodes of 3 and one of 1 -> 88/30 = 2.93
    assert "| turns | 2.93 |" in text
    # by domain: medical_qa holds MedQA's 10 items and LiveQA's 1
    assert "| medical_qa | " in text and "| visual_diagnosis | 66.7 [" in text
    assert "| multiple_choice | 75.0 [" in text
    # answered long-form and EHR episodes have no gold to be right against: no accuracy, only reward
    assert "| long_form | - | 0.0 [0.0, 0.0] | 1 |" in text and "| ehr_management | - | 40.0 [" in text
    assert f"`hcgym tasks import --format mmlu PATH/data/test/anatomy_test.csv --output {imported_tasks_dir('medical_qa')}/mmlu_anatomy.json`" in text
    assert (sft / "benchmarks.png").stat().st_size > 1000
    summary = json.loads((sft / "summary.json").read_text())["report"]
    medqa = next(b for b in summary["benchmarks"] if b["benchmark"] == "medqa")["metrics"][0]
    assert (medqa["n"], medqa["episodes"], medqa["estimate"]) == (10, 20, 0.75)


def test_condition_by_condition_report(folders):
    sft, rl = folders
    text = write_report(sft, others=[rl], n_resamples=500).read_text()
    assert "## Condition by condition" in text
    assert "| Benchmark | sft (agent) | rl (agent) |" in text
    assert "| medqa | 75.0 [" in text and "| 90.0 [" in text
    assert "| slake | - | 100.0 [100.0, 100.0] |" in text
    assert (sft / "conditions.png").stat().st_size > 1000


def test_compare_paired_differences_and_exact_mcnemar(folders, tmp_path, capsys):
    sft, rl = folders
    out = tmp_path / "cmp"
    assert compare.main([str(sft), str(rl), "--output", str(out), "--resamples", "2000"]) == 0
    data = json.loads((out / "comparison.json").read_text())
    medqa = data["benchmarks"][0]
    assert medqa["benchmark"] == "medqa" and medqa["items"] == 10 and medqa["episodes"] == 20
    assert medqa["a"] == pytest.approx(0.75) and medqa["b"] == pytest.approx(0.9)
    assert medqa["difference"]["estimate"] == pytest.approx(-0.15)
    # discordant episodes: A-only (m0,s0) (m0,s1) = 2; B-only (m7,s0) (m8,s0) (m9,s0) (m7,s1) (m8,s1) = 5
    # exact p = 2 * P(X <= 2 | n=7, 1/2) = 2 * (1 + 7 + 21) / 128
    assert (medqa["mcnemar"]["a_only"], medqa["mcnemar"]["b_only"]) == (2, 5)
    assert medqa["mcnemar"]["p_value"] == pytest.approx(58 / 128)
    item_diffs = [0.0] * 10
    item_diffs[0] = 1.0  # m0: A 1, B 0
    item_diffs[7] = item_diffs[8] = -1.0
    item_diffs[9] = -0.5  # m9: A 0.5, B 1
    ci = bootstrap_ci(item_diffs, n_resamples=2000)
    assert (medqa["difference"]["low"], medqa["difference"]["high"]) == pytest.approx((ci.low, ci.high))
    assert data["unshared"] == ["vqa_rad", "slake", "mimic3", "liveqa"]  # in paper18 order
    markdown = (out / "comparison.md").read_text()
    assert f"| medqa | accuracy | 10 | 75.0 | 90.0 | -15.0 [{100 * ci.low:+.1f}, {100 * ci.high:+.1f}] | 2 / 5 | 0.4531 |" in markdown
    assert "## Condition by condition" in markdown and "| medqa | 75.0 [" in markdown
    assert (out / "conditions.png").stat().st_size > 1000
    assert markdown.split("\n## Condition by condition")[0] in capsys.readouterr().out


def test_compare_rejects_a_folder_without_results(folders, tmp_path, capsys):
    assert compare.main([str(folders[0]), str(tmp_path)]) == 2
    assert f"{tmp_path}: not a results folder" in capsys.readouterr().err


def test_long_form_hallucination_and_comprehensiveness_from_the_task_statements():
    from envs.converters import convert
    from evals.metrics import summarise

    # must-have: "Face drooping is a warning sign", "Call emergency services immediately"; nice: the FAST acronym
    task = convert("medlfqa", FIX_BENCHMARKS / "medlfqa.jsonl").tasks[0]

    def row(text, seed=0):
        return {"benchmark": "liveqa", "task_id": task.id, "seed": seed, "answer": None, "gold": task.correct_answer,
                "end_reason": "answer", "extra": {"long_form_text": text}}

    complete = row("Face drooping is a warning sign of stroke. Call emergency services immediately.")
    contradicting = row("Face drooping is not a warning sign. Wait and see.", seed=1)
    by_metric = {m.name: m for m in summarise([complete], "long_form", {task.id: task}, n_resamples=100)}
    assert by_metric["comprehensiveness"].interval.estimate == 1.0  # both must-haves stated
    assert by_metric["hallucination"].interval.estimate == 0.0
    by_metric = {m.name: m for m in summarise([contradicting], "long_form", {task.id: task}, n_resamples=100)}
    assert by_metric["comprehensiveness"].interval.estimate == 0.0
    assert by_metric["hallucination"].interval.estimate == pytest.approx(1 / 3)  # 1 of 3 statements negated
    # two seeds of one item are one item: the mean of 0 and 1/3
    both = {m.name: m for m in summarise([complete, contradicting], "long_form", {task.id: task}, n_resamples=100)}
    assert both["hallucination"].interval.n == 1 and both["hallucination"].interval.estimate == pytest.approx(1 / 6)
    # without the task there are no statements: only ROUGE-L is reported
    assert [m.name for m in summarise([complete], "long_form", {}, n_resamples=100)] == ["rouge_l"]


def test_mmlu_med_is_broken_down_by_subject(tmp_path, monkeypatch):
    from envs.converters import convert
    from envs.core.task import dump_tasks, load_tasks
    from evals.suites import resolve

    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path / "data"))
    imported = tmp_path / "data" / "imported" / "medical_qa"
    medicine = tmp_path / "college_medicine_test.csv"
    medicine.write_text((FIX_BENCHMARKS / "anatomy_test.csv").read_text(encoding="utf-8"), encoding="utf-8")
    for source, name in ((FIX_BENCHMARKS / "anatomy_test.csv", "mmlu_anatomy"), (medicine, "mmlu_college_medicine")):
        dump_tasks(convert("mmlu", source).tasks, imported / f"{name}.json")
    items = resolve("mmlu_med").items
    assert len(items) == 4
    subject = {t.id: t.metadata["subject"] for p in imported.glob("*.json") for t in load_tasks(p, domain="medical_qa")}
    # anatomy: both right; college medicine: the first of its two right -> 100.0, 50.0, overall 75.0
    medicine_ids = sorted(i.task_id for i in items if subject[i.task_id] == "college_medicine")
    rows = [_row("sft", "mmlu_med", "medical_qa", i.task_id, i.task_id != medicine_ids[1]) for i in items]
    folder = tmp_path / "mmlu"
    folder.mkdir()
    pq.write_table(pa.Table.from_pylist([row_to_record(r) for r in rows]), folder / "results.parquet")
    spec = EvalSpec(policy="scripted:gold", policy_id="sft", suite="mmlu_med", condition="text", seeds=[0])
    (folder / "eval.json").write_text(spec.model_dump_json(), encoding="utf-8")
    text = write_report(folder, n_resamples=200).read_text()
    assert "| MC QA | MMLU-Med (6 sub.) | accuracy | 75.0 [" in text
    assert "| | &nbsp;&nbsp;subject: anatomy | accuracy | 100.0 [100.0, 100.0] | 2 | |" in text
    assert "| | &nbsp;&nbsp;subject: college_medicine | accuracy | 50.0 [0.0, 100.0] | 2 | |" in text


def test_compare_pairs_secondary_metrics_like_the_gym_reward():
    """A gym benchmark is compared on accuracy (with McNemar) and on its 5D reward (paired bootstrap)."""
    from evals.compare import compare_rows
    from evals.metrics import normalise_row

    def rows(policy, rewards):
        return [normalise_row(_row(policy, "gym_triage", "triage_emergency", f"t{i}", r >= 0.5, reward=r).model_dump())
                for i, r in enumerate(rewards)]

    a = rows("rl", [0.6, 0.4, 0.5, 0.3])
    b = rows("sft", [0.5, 0.4, 0.2, 0.3])
    result = compare_rows(a, b, {"gym_triage": "gym"}, n_resamples=500)
    (entry,) = result["benchmarks"]
    assert entry["metric"] == "accuracy" and entry["a"] == pytest.approx(0.5) and entry["b"] == pytest.approx(0.25)
    (reward,) = entry["secondary"]
    assert reward["metric"] == "reward" and reward["items"] == 4
    assert reward["a"] == pytest.approx(0.45) and reward["b"] == pytest.approx(0.35)
    assert reward["difference"]["estimate"] == pytest.approx(0.1)
    assert "mcnemar" not in reward
    markdown = compare.to_markdown(result, "rl", "sft")
    assert "| gym_triage | reward | 4 | 45.0 | 35.0 | +10.0 [" in markdown
