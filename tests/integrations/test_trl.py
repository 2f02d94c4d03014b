"""TRL 1.16 through `envs.integrations.trl`, with TRL's own code: the generated tool methods give
`transformers.utils.get_json_schema` (what TRL renders) the env's schemas in every domain, their calls
run through `env.call_tool`, the tiny model's tokenizer carries a response template TRL's parser
reads (TRL's `add_response_schema` refuses the project's chat template), and `GRPOTrainer` runs two
GRPO steps on CPU with the tiny model over exported tasks, its logged rewards per dimension equal to
the env's own reward components of the same rollouts."""

from __future__ import annotations

import inspect
import json
import math

import datasets
import pytest
from transformers.utils import get_json_schema

from envs import registry
from envs.env import HealthcareGymEnv
from envs.export import export_tasks
from envs.integrations.trl import (DIMENSIONS, REWARD_NAMES, environment_class, reward_functions,
                                   reward_weights)


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def _trl_tools(instance):
    """The methods TRL exposes as tools (its own selection rule in GRPOTrainer)."""
    return [getattr(instance, name) for name, _ in inspect.getmembers(type(instance), predicate=inspect.isfunction)
            if name not in ("reset", "get_reward") and not name.startswith("_")]


def _without_defaults(schema):
    # get_json_schema writes no `default`, and no empty `required`; everything else must match.
    schema = json.loads(json.dumps(schema))
    parameters = schema["function"]["parameters"]
    for prop in parameters.get("properties", {}).values():
        prop.pop("default", None)
    if not parameters.get("required"):
        parameters.pop("required", None)
    return schema


@pytest.mark.parametrize("domain", registry.list_domains())
def test_generated_tools_give_trl_the_env_schemas(domain):
    instance = environment_class(domain)()
    got = {tool.__name__: get_json_schema(tool) for tool in _trl_tools(instance)}
    want = {s["function"]["name"]: _without_defaults(s) for s in instance.env.tool_schemas}
    if domain == "cross_domain":  # composed per task at reset: the class offers every task's tools
        assert set(want) < set(got)
        got = {name: got[name] for name in want}
    assert got == want


def test_tool_calls_go_through_the_env_and_rewards_read_it():
    cls = environment_class("ward", max_turns=6)
    instance = cls()
    row = {"task_id": "ward_dose", "domain": "ward", "split": "train", "prompt": [], "tools": "[]", "answer": "{}"}
    assert instance.reset(**row) is None
    reference = HealthcareGymEnv(domain="ward", max_turns=6)
    reference.reset(options={"task_id": "ward_dose"})
    assert instance.dose_for_weight(patient_id="P2", mg_per_kg=15, max_mg=1000) == \
        reference.call_tool("dose_for_weight", {"patient_id": "P2", "mg_per_kg": 15, "max_mg": 1000}, message="").observation
    bad = instance.get_patient(patient_id="P404")
    assert "P404" in bad and not instance.env.done
    instance.submit_answer(answer="375")
    assert instance.env.end.reason == "answer"
    completion = [{"role": "assistant", "content": "ignored: the episode already ended"}]
    rewards = {f.__name__: f(completions=[completion], environments=[instance]) for f in reward_functions()}
    assert rewards == {f"reward_{n}": [instance.env.reward_components[n]] for n in REWARD_NAMES}
    assert rewards["reward_accuracy"] == [1.0] and list(cls.episodes) == [("ward_dose", instance.env.end)]
    # A rollout TRL stopped while it still called tools is a cut, not an answer.
    instance.reset(**row)
    end = instance._finish([{"role": "assistant", "content": "", "tool_calls": [{"type": "function"}]}])
    assert end.reason == "turn_limit"
    with pytest.raises(ValueError, match="task_id"):
        instance.reset(prompt=[])
    with pytest.raises(ValueError, match="domain 'ward'"):
        environment_class("drug_interaction")().reset(task_id="ward_dose", domain="ward")


def test_tokenizer_ships_a_response_template_trl_parses(tmp_path):
    from trl.chat_template_utils import add_response_schema, parse_response

    from modeling.model import load_tokenizer, train_tokenizer

    tokenizer = load_tokenizer(train_tokenizer(["a patient dose"] * 50, 300, tmp_path, max_stdlib_files=2))
    assert tokenizer.response_template is not None
    call = {"type": "function", "function": {"name": "get_patient", "arguments": {"patient_id": "P1"}}}
    messages = [{"role": "user", "content": "hi"}]
    prompt = tokenizer.apply_chat_template(messages, tokenize=False, add_generation_prompt=True)

    def parse(reply: str) -> dict:
        # As GRPOTrainer parses a completion: its ids after the prompt's ids.
        ids = lambda text: tokenizer(text, add_special_tokens=False)["input_ids"]  # noqa: E731
        return parse_response(tokenizer, ids(reply), prefix=ids(prompt), tools=None)

    for content in ("", "Let me look."):
        rendered = tokenizer.apply_chat_template(
            messages + [{"role": "assistant", "content": content, "tool_calls": [call]}], tokenize=False)
        parsed = parse(rendered[len(prompt):])
        assert parsed["tool_calls"] == [call] and parsed["content"].strip() == content
    assert parse("major.<|im_end|>\n") == {"role": "assistant", "content": "major."}
    # Without it TRL has nothing for this chat template (GRPOTrainer calls this when none is set).
    tokenizer.response_template = None
    with pytest.raises(ValueError, match="Unrecognized chat template"):
        add_response_schema(tokenizer)


def test_grpo_trainer_runs_two_steps_and_logs_the_env_rewards(tmp_path, monkeypatch):
    import torch
    from transformers import AutoModelForCausalLM
    from trl import GRPOConfig, GRPOTrainer

    from modeling.model import build_tiny_model, load_tokenizer, train_tokenizer

    monkeypatch.setenv("TRL_EXPERIMENTAL_SILENCE", "1")
    export_tasks(tmp_path / "data", domains=["ward"], fmt="parquet")
    dataset = datasets.load_dataset("parquet", data_files=str(tmp_path / "data" / "ward.parquet"), split="train")
    call = '<tool_call>\n{"name": "get_patient", "arguments": {"patient_id": "P2"}}\n</tool_call><|im_end|>'
    corpus = [m["content"] for row in dataset for m in row["prompt"]] + [row["tools"] for row in dataset] + [call]
    tok = train_tokenizer(corpus * 20, 512, tmp_path / "tok", max_stdlib_files=10)
    model_dir = build_tiny_model(tmp_path / "model", tok, seed=0, hidden_size=32, intermediate_size=64,
                                 num_hidden_layers=1, num_attention_heads=2, num_key_value_heads=1, head_dim=16)
    tokenizer = load_tokenizer(model_dir)
    model = AutoModelForCausalLM.from_pretrained(str(model_dir))
    cls = environment_class("ward")
    # A random model never calls a tool; a few supervised steps teach it to open its reply with one
    # after the prompt TRL renders (its tool block from the generated methods), so the rollouts run
    # TRL's tool loop through the environment.
    tools = _trl_tools(cls())
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    sequences = []
    for row in dataset:
        prompt = tokenizer.apply_chat_template(row["prompt"], tools=tools, add_generation_prompt=True, tokenize=False)
        prompt_ids, call_ids = (tokenizer(t, add_special_tokens=False)["input_ids"] for t in (prompt, call))
        sequences.append((torch.tensor([prompt_ids + call_ids]), torch.tensor([[-100] * len(prompt_ids) + call_ids])))
    for _ in range(40):
        for ids, labels in sequences:
            optimizer.zero_grad()
            model(input_ids=ids, labels=labels).loss.backward()
            optimizer.step()

    rollouts_per_step = 4
    args = GRPOConfig(output_dir=str(tmp_path / "out"), use_cpu=True, bf16=False, report_to="none", max_steps=2,
                      logging_steps=1, save_strategy="no", per_device_train_batch_size=rollouts_per_step,
                      num_generations=2, max_completion_length=160, temperature=0.05, max_tool_calling_iterations=1,
                      reward_weights=reward_weights(), seed=0, disable_tqdm=True)
    trainer = GRPOTrainer(model=model, processing_class=tokenizer, train_dataset=dataset,
                          environment_factory=cls, reward_funcs=reward_functions(), args=args)
    trainer.train()

    assert trainer.state.global_step == 2
    logged = [entry for entry in trainer.state.log_history if "rewards/reward_total/mean" in entry]
    episodes = list(cls.episodes)
    assert len(logged) == 2 and len(episodes) == 2 * rollouts_per_step
    assert {task_id for task_id, _ in episodes} <= set(dataset["task_id"])
    for step, entry in enumerate(logged):
        ends = [end for _, end in episodes[step * rollouts_per_step:(step + 1) * rollouts_per_step]]
        for name in REWARD_NAMES:
            env_mean = sum(end.reward_components[name] for end in ends) / len(ends)
            assert math.isclose(entry[f"rewards/reward_{name}/mean"], env_mean, abs_tol=1e-6), (step, name)
        # The trained reward is the env's total (weight 1 on total, 0 on the logged dimensions).
        assert math.isclose(entry["reward"], sum(e.reward for e in ends) / len(ends), abs_tol=1e-6)
        assert entry["tools/call_frequency"] > 0
    # TRL's tool loop ran the calls in the env: each episode recorded the call, answered by the tool.
    called = [turn["tool_calls"][0] for _, end in episodes for turn in end.episode["turns"] if turn["tool_calls"]]
    assert called and all(c["name"] == "get_patient" and c["error"] is None and "P2" in c["result"] for c in called)
    assert set(DIMENSIONS) <= set(episodes[0][1].reward_components)
