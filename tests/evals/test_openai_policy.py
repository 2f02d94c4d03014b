"""`evals.openai_policy` against a real OpenAI-compatible server: vLLM's CPU build on 127.0.0.1
serving a tiny model trained to answer / call a tool (tests/evals/conftest.py).

Failure modes the real server cannot produce on demand (429, 500, malformed bodies, slow answers)
come from `FaultProxy`, a small HTTP proxy in front of vLLM written here: it fails the next N
requests in a stated way and forwards everything else untouched. Context overflow is vLLM's own
400. Every test checks how many HTTP requests reached the proxy, so a lost or repeated request
(and tokens counted twice) would show.
"""

from __future__ import annotations

import asyncio
import base64
import json
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from datetime import UTC
from typing import Any

import pytest

from evals.conditions import action_text
from evals.openai_policy import (
    EndpointConfig,
    EndpointError,
    OpenAIChatPolicy,
    load_endpoint_options,
    parse_policy_string,
    policy_from_string,
    to_endpoint_messages,
)
from evals.types import Policy
from tests.evals.conftest import (
    ANSWER_TEXT,
    LETTER_ANSWER,
    LETTER_ONLY,
    LOOKUP_TOOL,
    SERVED_MODEL_NAME,
    TOOL_ARGUMENTS,
    TOOL_NAME,
    TOOLS_SYSTEM,
    TRAIN_QUESTIONS,
)

QUESTION = [{"role": "system", "content": TOOLS_SYSTEM}, {"role": "user", "content": TRAIN_QUESTIONS[0]}]
# The gym's own text-format prompt: the tools are listed in the system prompt, no `tools=`.
TEXT_TOOLS_SYSTEM = TOOLS_SYSTEM + "\n\n# Tools\n<tools>\n" + json.dumps(LOOKUP_TOOL) + "\n</tools>"


@dataclass
class Fault:
    """What the proxy does to one request instead of (or before) forwarding it."""

    kind: str  # "status" | "malformed" (a 200 with `body`) | "delay"
    status: int = 500
    headers: dict[str, str] = field(default_factory=dict)
    delay_s: float = 0.0
    body: str = '{"id": "x", "choices": [{"message": {"content": "The ans'


class FaultProxy:
    """An aiohttp server on 127.0.0.1 forwarding POSTs to the upstream server, failing the queued
    faults first (one per request, in order). Records every request body and header it received."""

    def __init__(self, upstream: str):
        self.upstream = upstream.rstrip("/")  # http://127.0.0.1:PORT (no /v1)
        self.faults: deque[Fault] = deque()
        self.received: list[dict[str, Any]] = []
        self.authorizations: list[str | None] = []
        self.forward_delay_s = 0.0
        self.in_flight = 0
        self.max_in_flight = 0
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()
        assert self._ready.wait(30), "fault proxy did not start"

    def reset(self, *faults: Fault, forward_delay_s: float = 0.0) -> None:
        self.faults = deque(faults)
        self.received.clear()
        self.authorizations.clear()
        self.forward_delay_s = forward_delay_s
        self.max_in_flight = 0

    def _serve(self) -> None:
        from aiohttp import ClientSession, web

        async def handle(request: web.Request) -> web.StreamResponse:
            raw = await request.read()
            self.received.append(json.loads(raw))
            self.authorizations.append(request.headers.get("Authorization"))
            self.in_flight += 1
            self.max_in_flight = max(self.max_in_flight, self.in_flight)
            try:
                fault = self.faults.popleft() if self.faults else None
                if fault is not None and fault.kind == "status":
                    return web.json_response({"error": {"message": f"injected {fault.status}", "code": fault.status}},
                                             status=fault.status, headers=fault.headers)
                if fault is not None and fault.kind == "malformed":
                    return web.Response(text=fault.body, content_type="application/json")
                await asyncio.sleep(fault.delay_s if fault is not None else self.forward_delay_s)
                async with ClientSession() as session, session.post(
                        self.upstream + request.path, data=raw, headers={"Content-Type": "application/json"}) as upstream:
                    return web.Response(body=await upstream.read(), status=upstream.status,
                                        content_type="application/json")
            finally:
                self.in_flight -= 1

        async def start() -> None:
            app = web.Application()
            app.router.add_post("/{tail:.*}", handle)
            self._runner = web.AppRunner(app)
            await self._runner.setup()
            site = web.TCPSite(self._runner, "127.0.0.1", 0)
            await site.start()
            self.port = site._server.sockets[0].getsockname()[1]
            self._ready.set()

        asyncio.set_event_loop(self._loop)
        self._loop.run_until_complete(start())
        self._loop.run_forever()

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self._runner.cleanup(), self._loop).result(30)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(30)


@pytest.fixture(scope="module")
def proxy(openai_server):
    server = FaultProxy(openai_server.removesuffix("/v1"))
    yield server
    server.close()


def make_policy(base_url: str, **options) -> OpenAIChatPolicy:
    fields = {"backoff_base_s": 0.05, "backoff_max_s": 5.0, "timeout_s": 30.0, **options}
    return OpenAIChatPolicy(EndpointConfig(base_url=base_url, model=SERVED_MODEL_NAME, **fields))


def reply(policy: OpenAIChatPolicy, messages=QUESTION, tools=None, max_tokens: int = 40, seed: int = 0):
    return asyncio.run(policy.reply(messages, tools, max_tokens=max_tokens, seed=seed))


def chat_template_tokens(model_dir: str, messages, tools=None) -> int:
    from transformers import AutoTokenizer

    tokenizer = AutoTokenizer.from_pretrained(model_dir)
    return len(tokenizer.apply_chat_template(messages, tools=tools, add_generation_prompt=True, tokenize=True,
                                             return_dict=True)["input_ids"])


def test_policy_strings_config_errors_and_key_handling(monkeypatch, tmp_path):
    assert parse_policy_string("openai:http://127.0.0.1:8000/v1:Qwen/Qwen3-8B") == (
        "http://127.0.0.1:8000/v1", "Qwen/Qwen3-8B")
    assert parse_policy_string("openai:http://host:11434/v1:llama3:8b") == ("http://host:11434/v1", "llama3:8b")
    assert parse_policy_string("openai:https://api.example.com:gpt-x") == ("https://api.example.com", "gpt-x")
    for bad in ("openai:127.0.0.1:8000:m", "openai:http://127.0.0.1:8000/v1", "vllm:http://h/v1:m"):
        with pytest.raises(ValueError, match="expected openai:BASE_URL:MODEL"):
            parse_policy_string(bad)
    with pytest.raises(ValueError, match="base_url"):
        EndpointConfig(base_url="127.0.0.1:8000", model="m")
    with pytest.raises(ValueError, match="concurrency"):
        EndpointConfig(base_url="http://h/v1", model="m", concurrency=0)
    monkeypatch.delenv("HCGYM_TEST_ENDPOINT_KEY", raising=False)
    with pytest.raises(ValueError, match="HCGYM_TEST_ENDPOINT_KEY"):
        policy_from_string("openai:http://h/v1:m", api_key_env="HCGYM_TEST_ENDPOINT_KEY")
    monkeypatch.setenv("HCGYM_TEST_ENDPOINT_KEY", "sk-secret-123")
    policy = policy_from_string("openai:http://h/v1:m", api_key_env="HCGYM_TEST_ENDPOINT_KEY")
    assert isinstance(policy, Policy) and policy.policy_id == "openai:http://h/v1:m"
    assert "sk-secret" not in repr(policy) + repr(policy.config) + policy.config.model_dump_json()
    config = tmp_path / "endpoint.yaml"
    config.write_text("tool_mode: text\nprice_input_per_1m: 0.5\n")
    assert policy_from_string("openai:http://h/v1:m", **load_endpoint_options(config)).config.tool_mode == "text"
    config.write_text("tool_mode: telepathy\n")
    with pytest.raises(ValueError, match=r"(?s)endpoint.yaml.*tool_mode"):
        load_endpoint_options(config)
    config.write_text("model: other\n")
    with pytest.raises(ValueError, match="'model' comes from the policy string"):
        load_endpoint_options(config)
    # Backoff: full jitter under base * 2**k (capped); a Retry-After (seconds or HTTP date) wins, capped.
    from datetime import datetime, timedelta
    from email.utils import format_datetime

    from evals.openai_policy import _retry_after_s

    jittered = OpenAIChatPolicy(EndpointConfig(base_url="http://h/v1", model="m", backoff_base_s=0.5,
                                               backoff_max_s=3.0))
    waits = [jittered._backoff_s(k, None) for k in range(6) for _ in range(50)]
    assert all(0 <= w <= min(3.0, 0.5 * 2 ** (i // 50)) for i, w in enumerate(waits))
    assert len({round(w, 6) for w in waits}) > 200  # jittered, not a fixed schedule
    assert jittered._backoff_s(0, 2.0) == 2.0 and jittered._backoff_s(0, 100.0) == 3.0
    in_ten = format_datetime(datetime.now(UTC) + timedelta(seconds=10), usegmt=True)
    assert 8.0 < _retry_after_s(in_ten) <= 10.0 and _retry_after_s("7") == 7.0 and _retry_after_s("soon") is None
    with pytest.raises(ValueError, match=r"messages\[1\].role"):
        to_endpoint_messages([{"role": "user", "content": "x"}, {"role": "robot", "content": "y"}])


def test_text_reply_usage_cost_and_api_key(proxy, endpoint_model_dir, monkeypatch):
    monkeypatch.setenv("HCGYM_TEST_ENDPOINT_KEY", "sk-secret-123")
    policy = make_policy(proxy.base_url, api_key_env="HCGYM_TEST_ENDPOINT_KEY", price_input_per_1m=2.0,
                         price_output_per_1m=8.0)
    proxy.reset()
    answer = reply(policy)
    assert answer.error_kind is None and answer.text == ANSWER_TEXT and answer.tool_calls is None
    assert answer.finish_reason == "stop"
    # Usage is the server's count of the chat-templated prompt (checked with the tokenizer itself).
    assert answer.prompt_tokens == chat_template_tokens(endpoint_model_dir, QUESTION)
    assert answer.completion_tokens >= 5
    assert answer.cost_usd == pytest.approx((answer.prompt_tokens * 2.0 + answer.completion_tokens * 8.0) / 1e6)
    assert proxy.authorizations == ["Bearer sk-secret-123"] and len(proxy.received) == 1
    assert proxy.received[0]["seed"] == 0 and "tools" not in proxy.received[0]
    # A token limit is the server's finish_reason "length".
    short = reply(policy, max_tokens=2)
    assert short.finish_reason == "length" and short.completion_tokens == 2
    assert policy.stats.prompt_tokens == answer.prompt_tokens + short.prompt_tokens
    # No price configured: no cost.
    assert reply(make_policy(proxy.base_url)).cost_usd is None


def test_native_and_text_tool_calls_reach_the_env_parser(proxy):
    from envs.core.actions import parse_action

    proxy.reset()
    native = make_policy(proxy.base_url)
    called = reply(native, tools=[LOOKUP_TOOL])
    assert called.error_kind is None and called.finish_reason == "tool_calls"
    assert [c["function"]["name"] for c in called.tool_calls] == [TOOL_NAME]
    assert json.loads(called.tool_calls[0]["function"]["arguments"]) == TOOL_ARGUMENTS
    assert proxy.received[0]["tools"] == [LOOKUP_TOOL]
    parsed = parse_action(action_text(called), {TOOL_NAME})
    assert [(c.name, c.arguments) for c in parsed.calls] == [(TOOL_NAME, TOOL_ARGUMENTS)]

    # The next turn carries the call and its result: vLLM accepts the converted history.
    history = QUESTION + [{"role": "assistant", "content": "", "tool_calls": called.tool_calls},
                          {"role": "tool", "content": "warfarin: vitamin K antagonist"}]
    sent = to_endpoint_messages(history)
    assert sent[-1]["tool_call_id"] == called.tool_calls[0]["id"]
    assert reply(native, messages=history, tools=[LOOKUP_TOOL]).error_kind is None

    # Text mode: no tools= on the wire; the model writes the Hermes block, the env parses it.
    text_policy = make_policy(proxy.base_url, tool_mode="text")
    proxy.reset()
    messages = [{"role": "system", "content": TEXT_TOOLS_SYSTEM}, QUESTION[1]]
    written = reply(text_policy, messages=messages, tools=[LOOKUP_TOOL])
    assert "tools" not in proxy.received[0] and written.tool_calls is None
    parsed = parse_action(action_text(written), {TOOL_NAME})
    assert [(c.name, c.arguments) for c in parsed.calls] == [(TOOL_NAME, TOOL_ARGUMENTS)]
    history = messages + [{"role": "assistant", "content": "", "tool_calls": called.tool_calls},
                          {"role": "tool", "content": "result"}]
    sent = to_endpoint_messages(history, tool_mode="text")
    assert [m["role"] for m in sent] == ["system", "user", "assistant", "user"]
    assert "<tool_call>" in sent[2]["content"] and sent[3]["content"].startswith("<tool_response>")
    assert reply(text_policy, messages=history).error_kind is None
    # Native mode, but the model wrote its call as text: the result goes back as text.
    history = messages + [{"role": "assistant", "content": written.text}, {"role": "tool", "content": "result"}]
    sent = to_endpoint_messages(history)
    assert sent[-1] == {"role": "user", "content": "<tool_response>\nresult\n</tool_response>"}
    assert reply(native, messages=history, tools=[LOOKUP_TOOL]).error_kind is None


def test_retries_on_429_and_500_then_success_counted_once(proxy):
    policy = make_policy(proxy.base_url, max_retries=3)
    clean = reply(policy)
    proxy.reset(Fault("status", 429, {"Retry-After": "1"}), Fault("status", 500), Fault("status", 503))
    started = time.monotonic()
    answer = reply(policy)
    assert time.monotonic() - started >= 1.0  # the Retry-After was waited
    assert answer.error_kind is None and answer.text == ANSWER_TEXT
    assert len(proxy.received) == 4  # 3 failures + 1 answer, nothing more
    assert (answer.prompt_tokens, answer.completion_tokens) == (clean.prompt_tokens, clean.completion_tokens)
    assert policy.stats.retries == 3 and policy.stats.attempts == 5 and policy.stats.requests == 2
    assert policy.stats.prompt_tokens == 2 * clean.prompt_tokens

    # More failures than retries: the reply names the last failure, no tokens, exactly 1 + max_retries tries.
    proxy.reset(*[Fault("status", 500)] * 4)
    failed = reply(policy)
    assert failed.error_kind == "http_500" and failed.text == "" and failed.prompt_tokens == 0
    assert len(proxy.received) == 4 and policy.stats.errors == {"http_500": 1}
    proxy.reset(*[Fault("status", 429)] * 2)
    assert reply(make_policy(proxy.base_url, max_retries=1)).error_kind == "http_429"
    assert len(proxy.received) == 2
    # A client error is not retried.
    proxy.reset(Fault("status", 401))
    assert reply(policy).error_kind == "http_401" and len(proxy.received) == 1


def test_timeouts_and_malformed_bodies(proxy):
    policy = make_policy(proxy.base_url, timeout_s=0.5, max_retries=1)
    proxy.reset(Fault("delay", delay_s=1.5))
    recovered = reply(policy)
    assert recovered.error_kind is None and recovered.text == ANSWER_TEXT and len(proxy.received) == 2
    proxy.reset(Fault("delay", delay_s=1.5), Fault("delay", delay_s=1.5))
    timed_out = reply(policy)
    assert timed_out.error_kind == "timeout" and timed_out.completion_tokens == 0 and len(proxy.received) == 2

    proxy.reset(Fault("malformed"))
    assert reply(policy).text == ANSWER_TEXT and len(proxy.received) == 2
    proxy.reset(Fault("malformed"), Fault("malformed"))
    malformed = reply(policy)
    assert malformed.error_kind == "malformed_json" and len(proxy.received) == 2
    # Valid JSON of the wrong shape is malformed too (a tool call without a name, no message).
    proxy.reset(Fault("malformed", body='{"choices": [{"message": {"tool_calls": [{"function": {}}]}}]}'),
                Fault("malformed", body='{"choices": [{"finish_reason": "stop"}], "usage": {"prompt_tokens": 9}}'))
    assert reply(policy).error_kind == "malformed_json" and len(proxy.received) == 2
    assert policy.stats.errors == {"timeout": 1, "malformed_json": 2}
    assert policy.stats.prompt_tokens == 2 * recovered.prompt_tokens  # nothing from the failed bodies
    time.sleep(1.2)  # let the proxy finish the slow requests it is still forwarding


def test_context_overflow_is_not_retried(proxy, caplog):
    policy = make_policy(proxy.base_url, max_retries=3)
    proxy.reset()
    too_long = [{"role": "user", "content": "warfarin " * 1500}]
    with caplog.at_level("WARNING", logger="evals.openai_policy"):
        overflow = reply(policy, messages=too_long)
    assert overflow.error_kind == "context_overflow" and overflow.prompt_tokens == 0
    assert len(proxy.received) == 1
    # The server's own words are shown once (vLLM: "This model's maximum context length is 1024 tokens ...").
    assert "maximum context length is 1024" in caplog.text


def test_concurrency_limit_holds_and_every_request_answers(proxy):
    policy = make_policy(proxy.base_url, concurrency=2)
    proxy.reset(forward_delay_s=0.3)

    async def many():
        return await asyncio.gather(*[policy.reply(QUESTION, None, max_tokens=8, seed=s) for s in range(6)])

    replies = asyncio.run(many())
    assert all(r.error_kind is None for r in replies) and len(proxy.received) == 6
    assert proxy.max_in_flight == 2
    assert sorted(body["seed"] for body in proxy.received) == list(range(6))


def test_images_go_as_base64_data_url_parts(proxy, tmp_path):
    image = tmp_path / "scan.png"
    image.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(64)))
    messages = [{"role": "user", "content": [{"type": "image", "image": str(image)},
                                             {"type": "text", "text": "What organ is shown?"}]}]
    proxy.reset()
    # The tiny model is text-only, so vLLM refuses the image: a reply with an error kind, sent once.
    refused = reply(make_policy(proxy.base_url), messages=messages)
    assert refused.error_kind == "image_unsupported" and len(proxy.received) == 1
    parts = proxy.received[0]["messages"][0]["content"]
    assert parts[1] == {"type": "text", "text": "What organ is shown?"}
    prefix = "data:image/png;base64,"
    url = parts[0]["image_url"]["url"]
    assert parts[0]["type"] == "image_url" and url.startswith(prefix)
    assert base64.b64decode(url[len(prefix):]) == image.read_bytes()
    # A text-only endpoint: the path as text, which the server answers.
    proxy.reset()
    answered = reply(make_policy(proxy.base_url, images="path_text"), messages=messages)
    assert answered.error_kind is None
    assert proxy.received[0]["messages"][0]["content"] == f"[image: {image}]\nWhat organ is shown?"
    with pytest.raises(FileNotFoundError, match="missing.png"):
        reply(make_policy(proxy.base_url), messages=[{"role": "user", "content": [
            {"type": "image", "image": str(tmp_path / "missing.png")}]}])


def test_option_logprobs_match_an_independent_forward_pass(proxy, endpoint_model_dir):
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    messages = [{"role": "system", "content": TOOLS_SYSTEM},
                {"role": "user", "content": TRAIN_QUESTIONS[1] + LETTER_ONLY}]
    letters = ["A", "B", "C", "D"]
    policy = make_policy(proxy.base_url)
    got = policy.option_logprobs(messages, letters)
    assert got is not None and set(got) == set(letters) and max(got, key=got.get) == LETTER_ANSWER

    tokenizer = AutoTokenizer.from_pretrained(endpoint_model_dir)
    model = AutoModelForCausalLM.from_pretrained(endpoint_model_dir, dtype=torch.float32).eval()
    ids = tokenizer.apply_chat_template(messages, add_generation_prompt=True, return_tensors="pt",
                                        return_dict=True)["input_ids"]
    with torch.no_grad():
        logprobs = torch.log_softmax(model(input_ids=ids).logits[0, -1], dim=-1)
    reported = {letter: value for letter, value in got.items() if value != float("-inf")}
    assert LETTER_ANSWER in reported
    for letter, value in reported.items():
        token_ids = [i for i in range(len(tokenizer)) if tokenizer.decode([i]).strip() == letter]
        expected = torch.logsumexp(logprobs[token_ids], dim=0).item()
        assert abs(value - expected) < 1e-3, (letter, value, expected)

    # From inside a running event loop too (the runner's), and None where disabled.
    async def inside_loop():
        return policy.option_logprobs(messages, letters)

    assert asyncio.run(inside_loop()) == pytest.approx(got, abs=1e-4)
    assert asyncio.run(policy.aoption_logprobs(messages, letters)) == pytest.approx(got, abs=1e-4)
    assert make_policy(proxy.base_url, logprobs=False).option_logprobs(messages, letters) is None
    proxy.reset(*[Fault("status", 500)] * 2)
    with pytest.raises(EndpointError, match="http_500"):
        make_policy(proxy.base_url, max_retries=1).option_logprobs(messages, letters)


def test_runner_turns_endpoint_failures_into_episodes_without_loss_or_double_counting(proxy, tmp_path):
    """The harness end to end (in-process envs): every failure is one episode row with its error
    kind, the rows' tokens add up to what the endpoint reported, and a re-run asks nothing again."""
    from envs import registry
    from evals.conditions import ConditionSettings
    from evals.runner import EvalOptions, run_eval
    from evals.types import EvalItem, read_results

    items = [EvalItem(benchmark="ward-endpoint", domain="ward", task_id=t.id) for t in registry.get_tasks("ward", None)]
    assert len(items) == 3
    policy = make_policy(proxy.base_url, max_retries=1)

    def evaluate(condition: str, retry_errors: bool = False):
        options = EvalOptions(condition=condition, use_ray=False, progress=False, concurrency=1,
                              settings=ConditionSettings(max_tokens=16, max_turns=2), retry_errors=retry_errors)
        run_eval(policy, items, tmp_path / condition, options, suite="ward-endpoint")
        return read_results(tmp_path / condition)

    # text: the first episode fails for good (500 twice), the next one is retried through a 429.
    proxy.reset(Fault("status", 500), Fault("status", 500), Fault("status", 429, {"Retry-After": "0"}))
    rows = evaluate("text")
    assert len(rows) == 3 and len({r.key() for r in rows}) == 3
    failed = [r for r in rows if r.end_reason == "endpoint_error"]
    assert [(r.error_kind, r.prompt_tokens, r.correct) for r in failed] == [("http_500", 0, False)]
    assert all(r.prompt_tokens > 0 and r.completion_tokens > 0 for r in rows if r not in failed)
    assert len(proxy.received) == 3 + 1 + 1  # one per episode, plus one retry each for the 500 and the 429
    assert sum(r.prompt_tokens for r in rows) == policy.stats.prompt_tokens
    assert sum(r.completion_tokens for r in rows) == policy.stats.completion_tokens

    # A finished folder is never recomputed: no request reaches the endpoint.
    proxy.reset()
    assert len(evaluate("text")) == 3 and proxy.received == []
    # --retry-errors: only the failed episode is asked again; it now succeeds and replaces its row.
    from evals.runner import pending_episodes

    assert pending_episodes(policy.policy_id, items, tmp_path / "text", "text", (0,), retry_errors=True) == 1
    kept = {r.key(): r for r in rows if r.end_reason != "endpoint_error"}
    rows = evaluate("text", retry_errors=True)
    assert len(proxy.received) == 1 and len(rows) == 3 and len({r.key() for r in rows}) == 3
    assert all(r.end_reason != "endpoint_error" and r.prompt_tokens > 0 for r in rows)
    assert all(r == kept[r.key()] for r in rows if r.key() in kept)  # the others untouched
    import pyarrow.parquet as pq

    trajectories = pq.read_table(tmp_path / "text" / "trajectories.parquet").to_pylist()
    assert sorted(t["row_id"] for t in trajectories) == sorted(r.trajectory_ref.split("#")[1] for r in rows)
    proxy.reset()

    # agent: the ward system prompt with its tools is longer than the server's 1024-token window,
    # so each episode ends at its first turn as a context overflow, asked once (not retried).
    rows = evaluate("agent")
    assert sorted(r.end_reason for r in rows) == ["context_overflow"] * 3
    assert {r.error_kind for r in rows} == {"context_overflow"} and all(r.turns == 0 for r in rows)
    assert len(proxy.received) == 3 and all("tools" in body for body in proxy.received)


def test_hcgym_eval_cli_with_an_endpoint_config(proxy, tmp_path, monkeypatch):
    """`hcgym eval --policy openai:URL:MODEL --endpoint-config FILE` as a user runs it: the file's key
    variable and prices reach every request and row."""
    from envs.cli import main
    from evals.policies import resolve_policy
    from evals.types import read_results

    monkeypatch.setenv("HCGYM_TEST_ENDPOINT_KEY", "sk-cli-456")
    config = tmp_path / "endpoint.yaml"
    config.write_text("api_key_env: HCGYM_TEST_ENDPOINT_KEY\nprice_input_per_1m: 1.0\nprice_output_per_1m: 4.0\n"
                      "max_retries: 0\ntool_mode: text\n")
    proxy.reset()
    out = tmp_path / "out"
    code = main(["eval", "--policy", f"openai:{proxy.base_url}:{SERVED_MODEL_NAME}", "--suite",
                 "gym-test:triage_emergency", "--condition", "text", "--limit", "2", "--max-tokens", "16",
                 "--output", str(out), "--no-ray", "--no-report", "--endpoint-config", str(config)])
    assert code == 0
    rows = read_results(out)
    assert len(rows) == 2 and len(proxy.received) == 2
    assert set(proxy.authorizations) == {"Bearer sk-cli-456"}
    for row in rows:
        assert row.policy_id == f"openai:{proxy.base_url}:{SERVED_MODEL_NAME}" and row.prompt_tokens > 0
        assert row.cost_usd == pytest.approx((row.prompt_tokens * 1.0 + row.completion_tokens * 4.0) / 1e6)
    with pytest.raises(ValueError, match="--endpoint-config applies to openai"):
        resolve_policy("scripted:gold", endpoint_config=str(config))
