"""A policy over any OpenAI-compatible chat-completions endpoint (vLLM, SGLang, llama.cpp, OpenAI, ...).

Policy strings: `openai:BASE_URL:MODEL`, e.g. `openai:http://127.0.0.1:8000/v1:Qwen/Qwen3-8B`. The
base URL ends at the first `:` after its path starts, so a model id may contain colons when the URL
has a path (`openai:http://host:11434/v1:llama3:8b`). In Python: `OpenAIChatPolicy(EndpointConfig(
base_url=..., model=...))`.

What it does per request (`reply`):
* Messages are sent as they are, except that the gym's image parts (`{"type": "image", "image":
  PATH}`, see `envs.env`) become OpenAI `image_url` parts with a base64 data URL (or, with
  `images="path_text"`, a text note for text-only endpoints).
* Tools: `tool_mode="native"` sends `tools=` and returns the endpoint's `tool_calls`;
  `tool_mode="text"` sends no `tools=` (the gym's system prompt already lists them) and the
  model writes Hermes `<tool_call>` blocks or JSON in its text, which `envs.core.actions` parses.
  Either way the history is converted to what the mode needs (see `to_endpoint_messages`).
* At most `concurrency` requests in flight per policy object and event loop.
* Retries with exponential backoff and full jitter on 429, 5xx, timeouts, connection errors and
  malformed bodies; a 429's `Retry-After` (seconds or an HTTP date) is waited instead when given.
  4xx other than 429 is not retried. A prompt over the context window (vLLM and OpenAI answer 400
  with "maximum context length") is `error_kind="context_overflow"`.
* A request that fails for good is a `PolicyReply` with `error_kind` (never an exception), so the
  runner records the episode. Token usage is the usage of the one attempt that answered (failed
  attempts report none), so nothing is counted twice; `stats` counts attempts, retries and errors.
* Cost: `price_input_per_1m` / `price_output_per_1m` (USD per million tokens) times the usage;
  None when no price is configured.

The API key is read from the environment variable named by `api_key_env` (default
OPENAI_API_KEY) at request time; it is never stored on the object, logged, or put in a repr.
Local servers need no key: when the default variable is unset no Authorization header is sent;
a variable named explicitly but unset is an error naming it.

Transport: aiohttp (already installed with `ray[default]`), one client session per call so a
policy object works from any event loop (the runner's, a Ray actor's, `option_logprobs`' own).
"""

from __future__ import annotations

import asyncio
import base64
import email.utils
import json
import logging
import math
import mimetypes
import os
import random
import re
import threading
import time
import weakref
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from evals.types import PolicyReply

logger = logging.getLogger(__name__)

DEFAULT_API_KEY_ENV = "OPENAI_API_KEY"
POLICY_PREFIX = "openai:"
# `openai:` + scheme://host[:port][/path without colons] + `:` + model id.
_POLICY_STRING = re.compile(r"^openai:(?P<base>https?://[^/\s]+(?:/[^:\s]*)?):(?P<model>\S+)$")
# How servers word "the prompt does not fit" (vLLM, OpenAI's code, llama.cpp, SGLang).
_CONTEXT_OVERFLOW = re.compile(
    r"maximum context length|context_length_exceeded|max_model_len|maximum model length|context window"
    r"|exceeds the context|longer than the model|too many tokens|prompt is too long", re.IGNORECASE)
# How servers word "this model takes no images" (vLLM, OpenAI).
_IMAGE_UNSUPPORTED = re.compile(
    r"not a multimodal model|does not support (image|vision|multimodal)|image input is not supported"
    r"|image_url is only supported", re.IGNORECASE)


class EndpointOptions(BaseModel):
    """How to use an OpenAI-compatible chat-completions endpoint (what `--endpoint-config` files hold)."""

    model_config = ConfigDict(extra="forbid")
    api_key_env: str = DEFAULT_API_KEY_ENV
    concurrency: int = Field(default=8, ge=1)
    timeout_s: float = Field(default=120.0, gt=0)  # whole request, per attempt
    connect_timeout_s: float = Field(default=10.0, gt=0)
    max_retries: int = Field(default=4, ge=0)  # retries after the first attempt
    backoff_base_s: float = Field(default=1.0, ge=0)  # attempt k waits U(0, base * 2**k), capped
    backoff_max_s: float = Field(default=60.0, ge=0)  # also caps a server's Retry-After
    tool_mode: Literal["native", "text"] = "native"
    images: Literal["content_parts", "path_text"] = "content_parts"
    temperature: float = Field(default=0.0, ge=0)
    top_p: float | None = Field(default=None, gt=0, le=1)
    top_logprobs: int = Field(default=20, ge=1)  # OpenAI's maximum; vLLM's default --max-logprobs
    logprobs: bool = True  # False: `option_logprobs` answers None without asking
    price_input_per_1m: float | None = Field(default=None, ge=0)
    price_output_per_1m: float | None = Field(default=None, ge=0)
    # Sent with every request (e.g. {"chat_template_kwargs": {"enable_thinking": False}} for vLLM).
    extra_body: dict[str, Any] = Field(default_factory=dict)


class EndpointConfig(EndpointOptions):
    """One endpoint: where it is (from the policy string) and how to use it."""

    base_url: str  # e.g. http://127.0.0.1:8000/v1 (requests go to {base_url}/chat/completions)
    model: str

    @field_validator("base_url")
    @classmethod
    def _http_url(cls, value: str) -> str:
        if not re.match(r"^https?://[^/\s]+", value):
            raise ValueError(f"base_url {value!r} is not an http(s) URL (e.g. http://127.0.0.1:8000/v1)")
        return value.rstrip("/")

    @field_validator("model")
    @classmethod
    def _model_given(cls, value: str) -> str:
        if not value.strip():
            raise ValueError("model is empty: name the model the endpoint serves")
        return value


def parse_policy_string(policy: str) -> tuple[str, str]:
    """Split `openai:BASE_URL:MODEL` into (base_url, model).

    Raises:
        ValueError: naming the string and the expected form.
    """
    match = _POLICY_STRING.match(policy.strip())
    # "openai:http://host:8000/v1" (no model) would otherwise read as model "8000/v1".
    if not match or re.match(r"^\d+(/|$)", match["model"]):
        raise ValueError(f"--policy {policy!r}: expected openai:BASE_URL:MODEL, e.g. "
                         "openai:http://127.0.0.1:8000/v1:my-model")
    return match["base"].rstrip("/"), match["model"]


def policy_from_string(policy: str, **options: Any) -> OpenAIChatPolicy:
    """An endpoint policy from `openai:BASE_URL:MODEL`, with further `EndpointConfig` fields as keywords."""
    base_url, model = parse_policy_string(policy)
    return OpenAIChatPolicy(EndpointConfig(base_url=base_url, model=model, **options))


def load_endpoint_options(path: str | os.PathLike) -> dict[str, Any]:
    """`EndpointConfig` fields (all but base_url and model, which the policy string gives) from a
    YAML or JSON file, e.g. `{tool_mode: text, price_input_per_1m: 0.15, api_key_env: MY_KEY}`.

    Raises:
        FileNotFoundError: naming the file.
        ValueError: naming the file and the field that is unknown or invalid.
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"endpoint config {path} does not exist")
    data = yaml.safe_load(path.read_text()) or {}
    if not isinstance(data, dict):
        raise ValueError(  # noqa: TRY004 (bad input is a ValueError naming the file, as everywhere here)
            f"{path}: expected a mapping of EndpointConfig fields, got {type(data).__name__}")
    for name in ("base_url", "model"):
        if name in data:
            raise ValueError(f"{path}: {name!r} comes from the policy string openai:BASE_URL:MODEL, not the file")
    try:
        EndpointOptions(**data)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    return data


class EndpointError(RuntimeError):
    """A request that failed for good (raised only by `option_logprobs`; `reply` returns the kind)."""

    def __init__(self, kind: str, detail: str):
        super().__init__(f"{kind}: {detail}")
        self.kind = kind
        self.detail = detail


class EndpointStats(BaseModel):
    """What one policy object has sent (attempts include retries)."""

    requests: int = 0  # calls of reply / option_logprobs
    attempts: int = 0  # HTTP requests sent
    retries: int = 0
    errors: dict[str, int] = Field(default_factory=dict)  # error_kind -> requests that failed for good
    prompt_tokens: int = 0
    completion_tokens: int = 0


# -- message conversion ----------------------------------------------------------------------------

def image_data_url(path: str | os.PathLike) -> str:
    """`data:<mime>;base64,...` for an image file.

    Raises:
        FileNotFoundError: naming the image path.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image {path} does not exist (task image_path)")
    mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


def _content(content: Any, images: str) -> Any:
    """Message content for the wire: gym image parts become image_url parts (or a text note)."""
    if not isinstance(content, list):
        return content
    parts: list[dict[str, Any]] = []
    for part in content:
        kind = part.get("type")
        if kind == "image":
            source = str(part.get("image") or "")
            if images == "path_text":
                parts.append({"type": "text", "text": f"[image: {source}]"})
            elif source.startswith(("http://", "https://", "data:")):
                parts.append({"type": "image_url", "image_url": {"url": source}})
            else:
                parts.append({"type": "image_url", "image_url": {"url": image_data_url(source)}})
        else:
            parts.append(part)
    if images == "path_text":
        # A text-only endpoint gets one string: some chat templates cannot render a list.
        return "\n".join(p.get("text", "") for p in parts)
    return parts


def _arguments_json(arguments: Any) -> str:
    return arguments if isinstance(arguments, str) else json.dumps(arguments, ensure_ascii=False)


def tool_calls_as_text(tool_calls: list[dict[str, Any]]) -> str:
    """OpenAI-shape tool calls as Hermes `<tool_call>` blocks (what `envs.core.actions` parses)."""
    blocks = []
    for call in tool_calls:
        function = call.get("function", call)
        arguments = function.get("arguments", {})
        if isinstance(arguments, str):
            try:
                arguments = json.loads(arguments)
            except json.JSONDecodeError:
                pass  # the env's parser reports an unreadable call to the agent
        blocks.append("<tool_call>\n" + json.dumps({"name": function.get("name"), "arguments": arguments},
                                                   ensure_ascii=False) + "\n</tool_call>")
    return "\n".join(blocks)


def to_endpoint_messages(messages: list[dict[str, Any]], *, tool_mode: str = "native",
                         images: str = "content_parts") -> list[dict[str, Any]]:
    """The chat history in the shape the endpoint accepts.

    native: assistant `tool_calls` get ids and JSON-string arguments; a `tool` message without
    `tool_call_id` gets the id of the assistant call it answers (in order); one that answers no
    native call (the model wrote its calls as text) becomes a `<tool_response>` user turn.
    text: assistant `tool_calls` become Hermes blocks in the content and `tool` messages become
    user turns with `<tool_response>` blocks (the training format), since an endpoint without
    `tools=` may refuse `tool` roles.
    """
    out: list[dict[str, Any]] = []
    pending_ids: list[str] = []
    for index, message in enumerate(messages):
        role = message.get("role")
        if role not in ("system", "user", "assistant", "tool"):
            raise ValueError(f"messages[{index}].role is {role!r}: expected system, user, assistant or tool")
        content = _content(message.get("content"), images)
        if role == "assistant" and message.get("tool_calls"):
            if tool_mode == "text":
                text = (content or "")
                calls = tool_calls_as_text(message["tool_calls"])
                out.append({"role": "assistant", "content": f"{text}\n{calls}" if text else calls})
                continue
            calls = []
            for number, call in enumerate(message["tool_calls"]):
                function = call.get("function", call)
                call_id = call.get("id") or f"call_{index}_{number}"
                calls.append({"id": call_id, "type": "function",
                              "function": {"name": function["name"],
                                           "arguments": _arguments_json(function.get("arguments", {}))}})
            pending_ids = [c["id"] for c in calls]
            out.append({"role": "assistant", "content": content or None, "tool_calls": calls})
            continue
        if role == "tool":
            text = content if isinstance(content, str) else json.dumps(content, ensure_ascii=False)
            # A result of calls the model wrote as text (no native call to answer) goes back as
            # text too: OpenAI refuses a `tool` message that follows no `tool_calls`.
            if tool_mode == "text" or (not pending_ids and not message.get("tool_call_id")):
                response = f"<tool_response>\n{text}\n</tool_response>"
                if out and out[-1]["role"] == "user" and str(out[-1]["content"]).startswith("<tool_response>"):
                    out[-1]["content"] += "\n" + response  # consecutive results share one user turn
                else:
                    out.append({"role": "user", "content": response})
                continue
            call_id = message.get("tool_call_id") or (pending_ids.pop(0) if pending_ids else f"call_{index}")
            out.append({"role": "tool", "tool_call_id": call_id, "content": text})
            continue
        out.append({"role": role, "content": content})
    return out


# -- responses -------------------------------------------------------------------------------------

def _retry_after_s(value: str | None) -> float | None:
    """Seconds to wait from a Retry-After header (delta-seconds or an HTTP date)."""
    if not value:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - time.time())


def _error_message(body: str) -> str:
    try:
        data = json.loads(body)
    except json.JSONDecodeError:
        return body[:500]
    error = data.get("error", data) if isinstance(data, dict) else data
    if isinstance(error, dict):
        return str(error.get("message") or error.get("code") or error)[:500]
    return str(error)[:500]


def read_completion(data: Any) -> tuple[str, list[dict[str, Any]] | None, int, int, str | None]:
    """(text, tool_calls in OpenAI shape or None, prompt_tokens, completion_tokens, finish_reason)
    of a chat-completions body.

    Raises:
        ValueError: naming what is missing or of the wrong type (the caller's `malformed_json`).
    """
    if not isinstance(data, dict) or not isinstance(data.get("choices"), list) or not data["choices"]:
        raise ValueError("no choices")
    choice = data["choices"][0]
    if not isinstance(choice, dict) or not isinstance(choice.get("message"), dict):
        raise ValueError("choices[0].message is missing")  # noqa: TRY004 (malformed body, see Raises)
    message = choice["message"]
    content = message.get("content")
    if isinstance(content, list):  # some servers answer in content parts
        content = "".join(part.get("text", "") for part in content if isinstance(part, dict))
    if content is not None and not isinstance(content, str):
        raise ValueError(f"choices[0].message.content is a {type(content).__name__}")
    tool_calls = None
    if message.get("tool_calls"):
        if not isinstance(message["tool_calls"], list):
            raise ValueError("choices[0].message.tool_calls is not a list")
        tool_calls = []
        for number, call in enumerate(message["tool_calls"]):
            function = call.get("function") if isinstance(call, dict) else None
            if not isinstance(function, dict) or not isinstance(function.get("name"), str):
                raise ValueError(  # noqa: TRY004 (malformed body, see Raises)
                    f"choices[0].message.tool_calls[{number}].function.name is missing")
            tool_calls.append({"id": call.get("id") or f"call_{number}", "type": call.get("type") or "function",
                               "function": {"name": function["name"],
                                            "arguments": _arguments_json(function.get("arguments") or {})}})
    usage = data.get("usage") or {}
    try:
        prompt_tokens = int(usage.get("prompt_tokens") or 0)
        completion_tokens = int(usage.get("completion_tokens") or 0)
    except (AttributeError, TypeError, ValueError):
        raise ValueError(f"usage is not token counts: {usage!r}"[:200]) from None
    return content or "", tool_calls, prompt_tokens, completion_tokens, choice.get("finish_reason")


class _Attempt(BaseModel):
    """The outcome of one HTTP attempt."""

    data: dict[str, Any] | None = None
    error_kind: str | None = None
    detail: str = ""
    retryable: bool = False
    retry_after_s: float | None = None


class OpenAIChatPolicy:
    """The `evals.types.Policy` protocol over an OpenAI-compatible chat-completions endpoint."""

    def __init__(self, config: EndpointConfig, policy_id: str | None = None):
        self.config = config
        self.policy_id = policy_id or f"openai:{config.base_url}:{config.model}"
        self.stats = EndpointStats()
        self._stats_lock = threading.Lock()
        # One semaphore per event loop (an asyncio semaphore is bound to the loop it first waits in);
        # weak keys, so the loops of finished `asyncio.run` calls do not pile up or alias.
        self._semaphores: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Semaphore] = (
            weakref.WeakKeyDictionary())
        self._logprobs_supported: bool | None = None
        self._warned_kinds: set[str] = set()
        self._check_api_key()

    def __repr__(self) -> str:  # no key in here, ever
        return f"OpenAIChatPolicy(policy_id={self.policy_id!r}, tool_mode={self.config.tool_mode!r})"

    # -- the Policy protocol -------------------------------------------------------------------
    async def reply(self, messages: list[dict[str, Any]], tools: list[dict[str, Any]] | None, *,
                    max_tokens: int, seed: int) -> PolicyReply:
        """One assistant turn; failures come back as a reply with `error_kind`, never raised
        (except a bad message list or a missing image file, which are the caller's bugs)."""
        body: dict[str, Any] = {
            "model": self.config.model,
            "messages": to_endpoint_messages(messages, tool_mode=self.config.tool_mode, images=self.config.images),
            "max_tokens": max_tokens,
            "seed": seed,
            "temperature": self.config.temperature,
        }
        if self.config.top_p is not None:
            body["top_p"] = self.config.top_p
        if tools and self.config.tool_mode == "native":
            body["tools"] = tools
            body["tool_choice"] = "auto"
        body.update(self.config.extra_body)
        attempt = await self._post(body)
        if attempt.data is None:
            return PolicyReply(error_kind=attempt.error_kind, finish_reason=None)
        return self._reply_from(attempt.data)

    def option_logprobs(self, messages: list[dict[str, Any]], letters: list[str]) -> dict[str, float] | None:
        """The Policy protocol's synchronous form of `aoption_logprobs` (blocks the calling thread;
        from a running event loop the request runs on a helper thread with its own loop)."""
        return _run_coroutine(self.aoption_logprobs(messages, letters))

    async def aoption_logprobs(self, messages: list[dict[str, Any]], letters: list[str]) -> dict[str, float] | None:
        """Log-probability of each option letter as the first token of the answer, from the
        endpoint's `top_logprobs` (one token, greedy).

        A letter's log-prob is the log-sum-exp over the top tokens that read as it once stripped
        ("B" and " B"). A letter outside the endpoint's top `top_logprobs` tokens is `-inf`
        (unknown, below every reported one), so the argmax is still the model's choice among the
        letters. Returns None when the endpoint gives no log-probs (no `logprobs` in the answer,
        or a 400 refusing the parameter; remembered) and when no letter is in the top tokens
        (nothing to choose from: the logprob condition records it as unavailable).

        Raises:
            EndpointError: When the request fails for good (timeouts, 5xx after the retries, ...).
        """
        if not self.config.logprobs or self._logprobs_supported is False:
            return None
        body = {
            "model": self.config.model,
            "messages": to_endpoint_messages(messages, tool_mode=self.config.tool_mode, images=self.config.images),
            "max_tokens": 1, "temperature": 0.0, "seed": 0,
            "logprobs": True, "top_logprobs": self.config.top_logprobs,
            **self.config.extra_body,
        }
        attempt = await self._post(body)
        if attempt.data is None:
            if attempt.error_kind == "http_400" and "logprob" in attempt.detail.lower():
                self._logprobs_supported = False
                return None
            raise EndpointError(attempt.error_kind or "endpoint_error", attempt.detail)
        try:
            first = attempt.data["choices"][0]["logprobs"]["content"][0]
            top = first["top_logprobs"]
        except (KeyError, IndexError, TypeError):
            self._logprobs_supported = False
            return None
        self._logprobs_supported = True
        by_letter: dict[str, list[float]] = {}
        for entry in top:
            token = str(entry.get("token", "")).strip()
            if token in letters and entry.get("logprob") is not None:
                by_letter.setdefault(token, []).append(float(entry["logprob"]))
        if not by_letter:
            logger.info("%s: no option letter among the top %d tokens", self.policy_id, self.config.top_logprobs)
            return None
        return {letter: _logsumexp(by_letter[letter]) if letter in by_letter else -math.inf for letter in letters}

    # -- transport -------------------------------------------------------------------------------
    def _semaphore(self) -> asyncio.Semaphore:
        loop = asyncio.get_running_loop()
        semaphore = self._semaphores.get(loop)
        if semaphore is None:
            semaphore = self._semaphores[loop] = asyncio.Semaphore(self.config.concurrency)
        return semaphore

    def _headers(self) -> dict[str, str]:
        headers = {"Content-Type": "application/json"}
        key = os.environ.get(self.config.api_key_env)
        if key:
            headers["Authorization"] = f"Bearer {key}"
        return headers

    def _check_api_key(self) -> None:
        if self.config.api_key_env != DEFAULT_API_KEY_ENV and not os.environ.get(self.config.api_key_env):
            raise ValueError(f"api_key_env: the environment variable {self.config.api_key_env!r} is not set "
                             "(it should hold the endpoint's API key)")

    def _count(self, **deltas: int) -> None:
        with self._stats_lock:
            for name, delta in deltas.items():
                setattr(self.stats, name, getattr(self.stats, name) + delta)

    def _count_error(self, kind: str) -> None:
        with self._stats_lock:
            self.stats.errors[kind] = self.stats.errors.get(kind, 0) + 1

    async def _post(self, body: dict[str, Any]) -> _Attempt:
        """POST with the concurrency limit and the retry policy; the final attempt's outcome."""
        import aiohttp

        self._count(requests=1)
        url = f"{self.config.base_url}/chat/completions"
        timeout = aiohttp.ClientTimeout(total=self.config.timeout_s, sock_connect=self.config.connect_timeout_s)
        payload = json.dumps(body, ensure_ascii=False)
        attempt = _Attempt(error_kind="endpoint_error")
        async with self._semaphore(), aiohttp.ClientSession(timeout=timeout) as session:
            for number in range(self.config.max_retries + 1):
                if number:
                    self._count(retries=1)
                    await asyncio.sleep(self._backoff_s(number - 1, attempt.retry_after_s))
                self._count(attempts=1)
                attempt = await self._attempt(session, url, payload)
                if attempt.data is not None or not attempt.retryable:
                    break
                logger.info("%s: attempt %d failed (%s: %s)", self.policy_id, number + 1, attempt.error_kind,
                            attempt.detail[:200])
        if attempt.data is None:
            kind = attempt.error_kind or "endpoint_error"
            self._count_error(kind)
            # The first failure of each kind is shown with the server's words (the rows keep only
            # the kind); later ones would flood a long evaluation's output.
            first = kind not in self._warned_kinds
            self._warned_kinds.add(kind)
            logger.log(logging.WARNING if first else logging.DEBUG, "%s: request failed for good after %d attempt(s): "
                       "%s: %s", self.policy_id, number + 1, kind, attempt.detail[:500])
        return attempt

    def _backoff_s(self, retry_index: int, retry_after_s: float | None) -> float:
        """Full-jitter exponential backoff; a server's Retry-After wins (capped at backoff_max_s)."""
        if retry_after_s is not None:
            return min(retry_after_s, self.config.backoff_max_s)
        ceiling = min(self.config.backoff_max_s, self.config.backoff_base_s * 2 ** retry_index)
        return random.uniform(0, ceiling)

    async def _attempt(self, session, url: str, payload: str) -> _Attempt:
        import aiohttp

        try:
            async with session.post(url, data=payload.encode("utf-8"), headers=self._headers()) as response:
                text = await response.text(errors="replace")
                status = response.status
                retry_after = _retry_after_s(response.headers.get("Retry-After"))
        except TimeoutError:
            return _Attempt(error_kind="timeout", detail=f"no answer within {self.config.timeout_s} s",
                            retryable=True)
        except aiohttp.ClientError as error:
            return _Attempt(error_kind="connection_error", detail=f"{type(error).__name__}: {error}", retryable=True)
        if status == 200:
            try:
                data = json.loads(text)
            except json.JSONDecodeError as error:
                return _Attempt(error_kind="malformed_json", detail=f"{error}: {text[:200]!r}", retryable=True)
            try:
                read_completion(data)
            except ValueError as error:
                return _Attempt(error_kind="malformed_json", detail=f"{error}: {text[:200]!r}", retryable=True)
            return _Attempt(data=data)
        message = _error_message(text)
        if status == 429:
            return _Attempt(error_kind="http_429", detail=message, retryable=True, retry_after_s=retry_after)
        if status >= 500:
            return _Attempt(error_kind=f"http_{status}", detail=message, retryable=True, retry_after_s=retry_after)
        if status in (400, 413, 422) and _CONTEXT_OVERFLOW.search(message):
            return _Attempt(error_kind="context_overflow", detail=message)
        if status in (400, 422) and _IMAGE_UNSUPPORTED.search(message):
            return _Attempt(error_kind="image_unsupported", detail=message)
        return _Attempt(error_kind=f"http_{status}", detail=message)

    def _reply_from(self, data: dict[str, Any]) -> PolicyReply:
        text, tool_calls, prompt_tokens, completion_tokens, finish_reason = read_completion(data)
        self._count(prompt_tokens=prompt_tokens, completion_tokens=completion_tokens)
        return PolicyReply(text=text, tool_calls=tool_calls, prompt_tokens=prompt_tokens,
                           completion_tokens=completion_tokens,
                           cost_usd=self.cost_usd(prompt_tokens, completion_tokens), finish_reason=finish_reason)

    def cost_usd(self, prompt_tokens: int, completion_tokens: int) -> float | None:
        """USD for this usage at the configured prices; None when no price is configured."""
        if self.config.price_input_per_1m is None and self.config.price_output_per_1m is None:
            return None
        return (prompt_tokens * (self.config.price_input_per_1m or 0.0)
                + completion_tokens * (self.config.price_output_per_1m or 0.0)) / 1e6


def _logsumexp(values: list[float]) -> float:
    top = max(values)
    return top + math.log(sum(math.exp(v - top) for v in values))


def _run_coroutine(coroutine):
    """Run a coroutine to completion from sync code, also when this thread already runs a loop
    (then on a helper thread with its own loop)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coroutine)
    result: dict[str, Any] = {}

    def target() -> None:
        try:
            result["value"] = asyncio.run(coroutine)
        except BaseException as error:  # noqa: BLE001 (re-raised in the caller's thread)
            result["error"] = error

    thread = threading.Thread(target=target, name="openai-policy-sync", daemon=True)
    thread.start()
    thread.join()
    if "error" in result:
        raise result["error"]
    return result["value"]
