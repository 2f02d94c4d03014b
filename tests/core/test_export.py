"""`hcgym tasks export`: rows read back by `datasets.load_dataset` (Parquet and JSONL), prompts built
from the env's prompt parts without the gold answer, tool schemas equal to the env's."""

from __future__ import annotations

import json

import datasets
import pytest

from envs import registry
from envs.cli import main
from envs.env import HealthcareGymEnv


def _load(path, fmt):
    return datasets.load_dataset("parquet" if fmt == "parquet" else "json", data_files=str(path), split="train")


@pytest.mark.parametrize(("domain", "fmt"), [("ward", "parquet"), ("cross_domain", "jsonl")])
def test_export_round_trips_through_load_dataset(tmp_path, capsys, domain, fmt):
    assert main(["tasks", "export", "--out", str(tmp_path), "--domain", domain, "--format", fmt]) == 0
    assert f"{domain}: " in capsys.readouterr().out
    rows = list(_load(tmp_path / f"{domain}.{fmt}", fmt))
    tasks = {t.id: t for t in registry.get_tasks(domain)}
    assert sorted(r["task_id"] for r in rows) == sorted(tasks)
    split_of = {i: split for split, ids in registry.get_splits(domain).items() for i in ids}
    env = HealthcareGymEnv(domain=domain)
    for row in rows:
        task = tasks[row["task_id"]]
        assert row["domain"] == domain and row["split"] == split_of[task.id]
        env.reset(options={"task_id": task.id})
        parts = env.prompt()
        assert row["prompt"] == [{"role": "system", "content": parts.system}, {"role": "user", "content": parts.ticket}]
        assert json.loads(row["tools"]) == env.tool_schemas == parts.tools
        answer = json.loads(row["answer"])
        assert answer["correct_answer"] == task.correct_answer and answer["answer_type"] == task.answer_type
        # The gold answer stays in the answer column: the prompt never carries it unless the task's
        # own ticket or policy does (a ticket may legitimately quote it, e.g. "confirm with 'recorded'").
        prompt_text = " ".join(m["content"] for m in row["prompt"])
        if task.correct_answer and task.correct_answer not in parts.ticket + parts.policy:
            assert task.correct_answer not in prompt_text, task.id


def test_a_distinctive_gold_answer_is_not_in_the_prompt(tmp_path):
    assert main(["tasks", "export", "--out", str(tmp_path), "--domain", "ward", "--split", "train"]) == 0
    rows = {r["task_id"]: r for r in _load(tmp_path / "ward.parquet", "parquet")}
    assert set(rows) == {"ward_dose", "ward_record"}
    dose = rows["ward_dose"]
    assert json.loads(dose["answer"])["correct_answer"] == "375"
    assert "375" not in json.dumps(dose["prompt"]) and "375" not in dose["tools"]


def test_bad_arguments_are_named(tmp_path, capsys):
    assert main(["tasks", "export", "--out", str(tmp_path), "--domain", "nope"]) == 2
    assert "--domain 'nope'" in capsys.readouterr().err
    assert main(["tasks", "export", "--out", str(tmp_path), "--domain", "ward", "--split", "holdout"]) == 2
    assert "--split 'holdout'" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
