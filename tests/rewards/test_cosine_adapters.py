"""Eq. 4 (cosine length reward) and the TRL / verl adapters, called the way those libraries call them."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.rewards import cosine_length_reward
from envs.rewards.adapters import compute_score, completion_to_trajectory, make_trl_reward, task_from_fields, trl_reward
from envs.rewards.cosine import assistant_tokens, episode_cosine_reward
from tests.rewards.builders import call, episode, mc_task, turn


# -- Eq. 4 -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("correct, length, expected", [
    (True, 0, 1.1), (True, 100, 0.7), (True, 50, 1.1 - 0.5 * 0.4 * 1.0), (True, 25, 1.1 - 0.2 * (1 - math.cos(math.pi / 4))),
    (False, 0, 0.0), (False, 100, -0.7), (False, 50, -0.35), (False, 75, -0.35 * (1 - math.cos(3 * math.pi / 4))),
])
def test_eq4_values(correct, length, expected):
    assert cosine_length_reward(correct, length, 100) == pytest.approx(expected)


def test_eq4_truncation_and_parameters():
    assert cosine_length_reward(True, 10, 100, truncated=True) == -0.5
    assert cosine_length_reward(False, 10, 100, truncated=True, r_penalty=-1.0) == -1.0
    assert cosine_length_reward(True, 0, 10, r_max=2.0, r_min=1.0) == 2.0
    assert cosine_length_reward(False, 10, 10, r_min=-0.7) == pytest.approx(-0.7)  # |R_min|
    assert cosine_length_reward(True, 500, 100) == pytest.approx(0.7)  # L clipped to L_max
    with pytest.raises(ValueError):
        cosine_length_reward(True, 1, 0)


@settings(max_examples=200, deadline=None)
@given(a=st.integers(0, 4096), b=st.integers(0, 4096))
def test_eq4_shorter_is_never_worse(a, b):
    lo, hi = min(a, b), max(a, b)
    for correct in (True, False):
        assert cosine_length_reward(correct, lo, 4096) >= cosine_length_reward(correct, hi, 4096) - 1e-12
    assert cosine_length_reward(True, hi, 4096) >= 0.7 - 1e-12 > 0 >= cosine_length_reward(False, lo, 4096)


def test_length_counts_all_assistant_turns():
    task = mc_task()
    traj = episode(task, turn(message="one two three", fmt="text"), answer="D")
    traj.turns[-1].action = "four five"
    assert assistant_tokens(traj) == 5
    assert assistant_tokens(traj, count=len) == len("one two three") + len("four five")

    class Tok:
        def encode(self, text, add_special_tokens=True):
            assert add_special_tokens is False
            return list(text)

    assert assistant_tokens(traj, tokenizer=Tok()) == len("one two three") + len("four five")
    assert episode_cosine_reward(traj, True, 10) == pytest.approx(cosine_length_reward(True, 5, 10))
    traj.truncated = True
    assert episode_cosine_reward(traj, True, 10) == -0.5


# -- TRL: reward_func(prompts, completions, **dataset_columns) -> list[float] ------------------------
def test_trl_standard_format_with_dataset_columns():
    prompts = ["Which deficiency causes rickets?"] * 3
    completions = ["Rickets follows low vitamin D.\nAnswer: D", "Answer: A or D", "Answer: B"]
    options = [{"A": "Vitamin A", "B": "Vitamin C", "C": "Iron", "D": "Vitamin D"}] * 3
    rewards = trl_reward(prompts=prompts, completions=completions, correct_answer=["D"] * 3, options=options,
                         trainer_state=None, completion_ids=[[1], [2], [3]])
    assert isinstance(rewards, list) and all(isinstance(r, float) for r in rewards)
    assert rewards[0] == pytest.approx(1.0)
    assert rewards[0] > rewards[2] and rewards[0] > rewards[1]
    assert trl_reward.__name__ == "healthcare_gym_reward"


def test_trl_conversational_format_with_tool_calls_and_task_column():
    task = mc_task("D")
    prompts = [[{"role": "system", "content": "You are a doctor."}, {"role": "user", "content": task.ticket}]]
    completions = [[
        {"role": "assistant", "content": '<tool_call>{"name": "search_pubmed", "arguments": {"query": "rickets"}}</tool_call>'},
        {"role": "tool", "content": '[{"doc_id": "pubmed_1", "title": "Rickets and vitamin D"}]'},
        {"role": "assistant", "content": '<tool_call>{"name": "submit_answer", "arguments": {"answer": "D"}}</tool_call>'},
    ]]
    reward = make_trl_reward(name="hc")
    assert reward(prompts, completions, task=[task.model_dump(mode="json")]) == [pytest.approx(1.0)]
    traj = completion_to_trajectory(completions[0], task)
    assert [t.action_format for t in traj.turns] == ["hermes", "hermes"]
    assert traj.submitted_answer == "D" and traj.turns[0].tool_calls[0].result.startswith("[{")


def test_task_from_fields_variants():
    assert task_from_fields({"answer": "B", "options": '["x", "y", "z"]'}).options == {"A": "x", "B": "y", "C": "z"}
    t = task_from_fields({"answer": "Paris"}, "Capital of France?")
    assert t.answer_type == "exact" and t.ticket == "Capital of France?"
    assert task_from_fields({"answer": "Z", "options": {"A": "a", "B": "b"}}).answer_type == "exact"


# -- verl: compute_score(data_source, solution_str, ground_truth, extra_info) ------------------------
def test_verl_compute_score_keyword_call_like_the_reward_manager():
    extra = {"options": {"A": "Vitamin A", "B": "Vitamin C", "C": "Iron", "D": "Vitamin D"},
             "question": "Which deficiency causes rickets?", "index": 7, "split": "train"}
    good = compute_score(data_source="healthcare_gym/medical_qa", solution_str="Vitamin D deficiency.\nAnswer: D",
                         ground_truth="D", extra_info=extra)
    bad = compute_score(data_source="healthcare_gym/medical_qa", solution_str="Answer: C", ground_truth="D", extra_info=extra)
    assert good["score"] == pytest.approx(1.0) and good["acc"] == 1.0
    assert bad["acc"] == 0.0 and bad["score"] < good["score"]
    assert set(good) == set(bad) == {"score", "acc", "accuracy", "process", "safety", "format", "coherence", "safety_penalty"}
    assert all(isinstance(v, float) for v in good.values())


def test_verl_task_as_json_ground_truth_and_positional_call():
    task = mc_task("D")
    result = compute_score("src", "Answer: D", task.model_dump_json(), None)
    assert result["acc"] == 1.0
    with_task = compute_score("src", "Answer: A", "ignored", {"task": task.model_dump(mode="json")})
    assert with_task["acc"] == 0.0


def test_adapters_score_tool_calls_like_the_environment():
    task = mc_task("D")
    fenced = completion_to_trajectory('```json\n{"name": "submit_answer", "arguments": {"answer": "D"}}\n```', task)
    assert fenced.turns[0].action_format == "fenced" and fenced.submitted_answer == "D"
    function = completion_to_trajectory('submit_answer(answer="D")', task)
    assert function.turns[0].tool_calls[0].format == "function"
    assert call("x").format == "hermes"


def test_score_episodes_encodes_free_text_in_one_batch():
    import hashlib

    import numpy as np

    from envs.core.task import Task
    from envs.rewards import score_episode, score_episodes, similarity

    calls: list[int] = []

    def fake(texts):
        calls.append(len(texts))
        out = []
        for t in texts:
            v = np.frombuffer(hashlib.sha256(t.lower().encode()).digest(), dtype=np.uint8).astype(np.float32)
            out.append(v / np.linalg.norm(v))
        return np.stack(out)

    task = Task(ticket="Most likely result?", correct_answer="Pneumothorax due to pleural injury", answer_type="free_text")
    items = [(episode(task, answer=a), task) for a in ("pneumothorax", "collapsed lung", "rotator cuff tear")]
    similarity.set_embedder(fake, "fake")
    batch = score_episodes(items)
    assert calls == [4]  # three answers and the gold, once
    singles = [score_episode(t, k) for t, k in items]
    assert calls == [4]  # all cached
    assert [b.total for b in batch] == [s.total for s in singles]
    assert all(b.details["accuracy"]["semantic"] for b in batch)
