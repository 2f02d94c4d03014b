"""Policy resolution from the --policy string, run folders, prompt parity with training, scripted
baselines. Real files and the tiny ward policy throughout."""

from __future__ import annotations

import asyncio
import json
import shutil
from pathlib import Path

import pytest
import yaml

from actors.agent_loop import AgentLoop, LocalEnv, RolloutLimits
from evals.conditions import episode_spec
from evals.policies import (
    LocalModelPolicy,
    ScriptedPolicy,
    majority_letters,
    render_messages,
    resolve_policy,
    run_policy,
)
from tests.evals.conftest import WARD

pytestmark = pytest.mark.usefixtures("ward_domain")


def ward_tasks():
    from envs import registry

    return {t.id: t for t in registry.get_tasks("ward", None)}


def test_bad_policy_strings_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match="scripted:oracle.*scripted:gold"):
        resolve_policy("scripted:oracle")
    with pytest.raises(ValueError, match="--policy 'no/such/dir/x'"):
        resolve_policy("no/such/dir/x")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="no config.json"):
        resolve_policy(str(tmp_path / "empty"))
    with pytest.raises(FileNotFoundError, match="not in the Hugging Face cache"):
        resolve_policy("nobody-here/absent-model")


def make_run_dir(root: Path, policy_dir: str, *, checkpoint: bool) -> Path:
    """A run folder laid out as `hcgym train` writes it: config, warm start, optionally a checkpoint."""
    run = root / "run"
    (run / "model").mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump({
        "rollout": {"system_prompt": "compact", "max_turns": 3, "max_new_tokens_per_turn": 24,
                    "max_response_tokens": 200},
        "data": {"domain_modules": WARD}}))
    (run / "model" / "policy.json").write_text(json.dumps({"policy_dir": policy_dir}))
    if checkpoint:
        target = run / "checkpoints" / "step_000002" / "learner" / "policy"
        shutil.copytree(policy_dir, target)
        (run / "checkpoints" / "latest").write_text("step_000002")
    return run


def test_run_folder_resolves_to_its_latest_checkpoint_else_its_warm_start(tmp_path, ward_policy_dir):
    run = make_run_dir(tmp_path / "a", ward_policy_dir, checkpoint=False)
    found = run_policy(run)
    assert found.model_dir == Path(ward_policy_dir) and found.source.startswith("warm start")
    assert (found.prompt_style, found.domain_modules) == ("compact", WARD)
    run = make_run_dir(tmp_path / "b", ward_policy_dir, checkpoint=True)
    policy, notes = resolve_policy(str(run))
    assert isinstance(policy, LocalModelPolicy)
    assert policy.model_dir == run / "checkpoints" / "step_000002" / "learner" / "policy"
    assert notes["source"] == "checkpoint step_000002" and policy.prompt_style == "compact"
    empty = tmp_path / "c"
    (empty / "model").mkdir(parents=True)
    (empty / "config.yaml").write_text("{}")
    with pytest.raises(FileNotFoundError, match="no finished checkpoint"):
        run_policy(empty)


def test_rendered_messages_are_what_the_training_agent_loop_sees(ward_policy_dir):
    """The agent condition re-renders the chat; the text must equal the TITO layout of training."""
    policy = LocalModelPolicy(ward_policy_dir)
    tok = policy.tokenizer
    env = LocalEnv(3)
    _, info = asyncio.run(env.reset(episode_spec("ward_dose", "ward", None, 0)))
    loop = AgentLoop(tok, RolloutLimits(max_turns=3), prompt_style="env")
    messages = [{"role": "system", "content": info["system_prompt"]}, {"role": "user", "content": info["ticket"]}]
    assert render_messages(tok, messages) == loop.render_prompt(info)
    action = '<tool_call>{"name": "get_patient", "arguments": {"patient_id": "P2"}}</tool_call>'
    observation = '{"patient_id": "P2", "weight_kg": 25}'
    tito_text = (tok.decode(loop.render_prompt(info)) + action + "<|im_end|>"
                 + loop.observation_text(observation, had_tool_calls=True))
    rendered = tok.apply_chat_template(messages + [{"role": "assistant", "content": action},
                                                   {"role": "tool", "content": observation}],
                                       tokenize=False, add_generation_prompt=True)
    assert rendered == tito_text


def test_local_model_reply_is_deterministic_and_counts_tokens(ward_policy_dir):
    policy = LocalModelPolicy(ward_policy_dir)
    messages = [{"role": "system", "content": "You are a ward assistant."}, {"role": "user", "content": "Hello"}]

    async def twice():
        return [await policy.reply(messages, None, max_tokens=12, seed=7) for _ in range(2)]

    first, second = asyncio.run(twice())
    assert first == second and first.error_kind is None
    assert first.prompt_tokens == len(render_messages(policy.tokenizer, messages))
    assert 1 <= first.completion_tokens <= 12 and first.finish_reason in ("stop", "length")
    assert policy.max_context_tokens == 20480  # the model's max_position_embeddings (TINY_MODEL_DEFAULTS)
    tight = LocalModelPolicy(ward_policy_dir, max_context_tokens=8)
    overflow = asyncio.run(tight.reply(messages, None, max_tokens=4, seed=0))
    assert overflow.error_kind == "context_overflow" and overflow.completion_tokens == 0


def test_scripted_baselines():
    tasks = ward_tasks()
    choice = tasks["ward_choice"]
    draws = {ScriptedPolicy("random").for_episode(choice, seed, "ward").answer for seed in range(40)}
    assert draws == {"A", "B", "C", "D"}  # every option gets drawn over seeds
    assert ScriptedPolicy("random").answer_for(choice, 3, "ward") == ScriptedPolicy("random").answer_for(choice, 3, "ward")
    assert ScriptedPolicy("random").answer_for(tasks["ward_dose"], 0, "ward") == ""  # no options: abstains
    assert ScriptedPolicy("gold").answer_for(tasks["ward_dose"], 0, "ward") == "375"
    letters = majority_letters({"b1": [choice, choice], "b2": [tasks["ward_dose"]]})
    assert letters == {"b1": "B"}
    majority = ScriptedPolicy("majority", letters)
    assert majority.answer_for(choice, 0, "b1") == "B"
    assert majority.for_episode(choice, 0, "b1").option_logprobs([], ["A", "B"]) == {"A": float("-inf"), "B": 0.0}
    with pytest.raises(RuntimeError, match="needs the task"):
        asyncio.run(majority.reply([], None, max_tokens=1, seed=0))
