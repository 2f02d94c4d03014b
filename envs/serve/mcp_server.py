"""HealthcareGym over MCP (streamable HTTP), for any agent that speaks MCP.

MCP has no reset and no reward, so the server adds episode tools beside the task's tools:
`start_episode` (returns the episode id and the prompt parts), `finish_episode` (ends and scores it)
and `episode_result`. The call that ends an episode (a submit, a limit, `finish_episode`) carries the
score in its result. The task's tools are listed with their schemas verbatim (the env's
`tool_schemas` `parameters`), and every call runs through the env's one episode core
(`HealthcareGymEnv.call_tool` / `finish`), so an episode scores the same here as in process.

Episodes are keyed by an id, not by the MCP session: requests negotiated at protocol 2026-07-28
carry no session id, so a call names its episode in the request `_meta` (`EPISODE_META_KEY`) or in an
`episode_id` argument; on the legacy (handshake) protocol the episode last started in the
`Mcp-Session-Id` session is the default.
"""

from __future__ import annotations

import json
import threading
import time
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import anyio
import mcp_types as types
from mcp.server.lowlevel import Server
from mcp.shared.exceptions import MCPError
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from envs.env import HealthcareGymEnv
from envs.episode import END_REASONS, EpisodeEnd
from envs.serve.guard import H11_MAX_HEAD, HTTPGuard, guarded_protocol
# The settings and the token rule are shared with the OpenEnv server; re-exported here for callers.
from envs.serve.settings import LOOPBACK_HOSTS, BearerToken, ServeSettings, is_loopback  # noqa: F401

EPISODE_META_KEY = "hcgym/episode_id"
# The assistant text of the turn a call belongs to: the call opens a new assistant turn with it.
MESSAGE_META_KEY = "hcgym/message"
# True: the call joins the open assistant turn instead of opening one (several calls, one turn).
SAME_TURN_META_KEY = "hcgym/same_turn"
SESSION_HEADER = "mcp-session-id"
EPISODE_TOOLS = ("start_episode", "finish_episode", "episode_result")
MAX_TOOL_NAME_CHARS = 128  # the MCP specification's bound on a tool name
MAX_EPISODE_ID_CHARS = 64  # ids are 32 hex digits; anything much longer is not one


class StartArgs(BaseModel):
    model_config = ConfigDict(extra="forbid")
    domain: str | None = Field(None, max_length=64)
    task_id: str | None = Field(None, max_length=256)
    split: str | None = Field(None, max_length=32)
    seed: int | None = Field(None, ge=0, le=2**63 - 1)  # the env's generator takes a non-negative seed


class FinishArgs(BaseModel):
    model_config = ConfigDict(extra="forbid")
    episode_id: str | None = Field(None, max_length=MAX_EPISODE_ID_CHARS)
    final_text: str | None = None
    reason: str | None = Field(None, max_length=64)


class ResultArgs(BaseModel):
    model_config = ConfigDict(extra="forbid")
    episode_id: str | None = Field(None, max_length=MAX_EPISODE_ID_CHARS)


def shown(value: Any, limit: int = 60) -> str:
    """`value` for an error message: its repr, cut (with its length named) when long."""
    text = repr(value)
    if len(text) <= limit:
        return text
    size = f" ({len(value)} characters)" if isinstance(value, str) else ""
    return f"{text[:limit]}...{size}"


class ToolCallError(Exception):
    """A call the server refuses; its text is the tool error the client sees."""


class BusyError(ToolCallError):
    pass


@dataclass
class Episode:
    id: str
    domain: str
    env: HealthcareGymEnv | None
    task_id: str
    last_used: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    end: EpisodeEnd | None = None


def score_of(end: EpisodeEnd) -> dict[str, Any]:
    """The score a client sees: total, the components, how it ended."""
    return {"reason": end.reason, "reward": end.reward, "reward_components": dict(end.reward_components),
            "terminated": end.terminated, "truncated": end.truncated, "is_correct": end.is_correct,
            "submitted_answer": end.submitted_answer, "safety_violations": dict(end.safety_violations),
            "grader_error": end.grader_error, "env_error": end.env_error}


class EpisodeStore:
    """The running episodes: at most `max_episodes` running; idle ones dropped; ended ones keep only
    their score (their env is released) until they too go idle, the newest `max_finished` of them."""

    def __init__(self, settings: ServeSettings, clock=time.monotonic) -> None:
        self.settings = settings
        self.clock = clock
        self._episodes: dict[str, Episode] = {}
        self._by_session: dict[str, str] = {}
        # ended episodes in the order they ended: a flood of short episodes must not keep every score
        self._finished: OrderedDict[str, None] = OrderedDict()
        self._lock = threading.Lock()

    def _reap(self) -> None:
        cutoff = self.clock() - self.settings.idle_timeout_s
        for eid in [e.id for e in self._episodes.values() if e.last_used < cutoff]:
            del self._episodes[eid]
            self._finished.pop(eid, None)
        for sid in [s for s, eid in self._by_session.items() if eid not in self._episodes]:
            del self._by_session[sid]

    def running(self) -> int:
        with self._lock:
            self._reap()
            return sum(1 for e in self._episodes.values() if e.end is None)

    def start(self, args: StartArgs, session_id: str | None) -> tuple[Episode, dict[str, Any]]:
        domain = args.domain or self.settings.domains[0]
        if domain not in self.settings.domains:
            raise ToolCallError(f"start_episode: argument 'domain': {shown(domain)} is not served here "
                                f"(served: {', '.join(self.settings.domains)})")
        split = args.split if args.split is not None else self.settings.split
        with self._lock:
            self._reap()
            if sum(1 for e in self._episodes.values() if e.end is None) >= self.settings.max_episodes:
                raise BusyError(f"busy: {self.settings.max_episodes} episodes are running (the server's "
                                "--max-episodes); finish one or retry later")
            eid = uuid.uuid4().hex
            # Reserve the slot before building the env (outside the lock) so the bound holds under a burst.
            reserved = Episode(id=eid, domain=domain, env=None, task_id="", last_used=self.clock())
            self._episodes[eid] = reserved
        try:
            env = HealthcareGymEnv(domain=domain, split=split, max_turns=self.settings.max_turns,
                                   max_tool_calls=self.settings.max_tool_calls,
                                   max_tool_result_chars=self.settings.max_tool_result_chars)
            options = {"task_id": args.task_id} if args.task_id is not None else None
            env.reset(seed=args.seed, options=options)
        except (KeyError, ValueError) as exc:
            with self._lock:
                self._episodes.pop(eid, None)
            name = "task_id" if isinstance(exc, KeyError) else "split"
            raise ToolCallError(f"start_episode: argument {name!r}: {exc.args[0] if exc.args else exc}") from exc
        except BaseException:
            with self._lock:
                self._episodes.pop(eid, None)
            raise
        with self._lock:
            reserved.env, reserved.task_id, reserved.last_used = env, env.task.id, self.clock()
            if session_id:
                self._by_session[session_id] = eid
        parts = env.prompt()
        return reserved, {"episode_id": eid, "domain": domain, "task_id": env.task.id, "split": split,
                             "prompt": parts.model_dump(), "messages": parts.messages()}

    def get(self, episode_id: str | None, session_id: str | None) -> Episode:
        with self._lock:
            self._reap()
            if episode_id is None and session_id:
                episode_id = self._by_session.get(session_id)
            if episode_id is None:
                raise ToolCallError(f"no episode named: call start_episode first and pass its episode_id in the "
                                    f"request _meta ({EPISODE_META_KEY!r}) or as an 'episode_id' argument")
            if len(episode_id) > MAX_EPISODE_ID_CHARS:
                raise ToolCallError(f"argument 'episode_id': {shown(episode_id)} is not an episode id (at most "
                                    f"{MAX_EPISODE_ID_CHARS} characters)")
            episode = self._episodes.get(episode_id)
            if episode is None or episode.env is None and episode.end is None:
                raise ToolCallError(f"argument 'episode_id': unknown or expired episode {shown(episode_id)} "
                                    f"(episodes idle for {self.settings.idle_timeout_s:g} s are dropped, and only "
                                    f"the last {self.settings.max_finished} ended episodes keep their score)")
            episode.last_used = self.clock()
            return episode

    def ended(self, episode: Episode, end: EpisodeEnd) -> None:
        with self._lock:
            episode.end, episode.env = end, None  # release the env: an ended episode holds only its score
            self._finished[episode.id] = None
            while len(self._finished) > self.settings.max_finished:
                oldest, _ = self._finished.popitem(last=False)
                self._episodes.pop(oldest, None)

    def finished(self) -> int:
        """Ended episodes whose score is kept."""
        with self._lock:
            return len(self._finished)


def _text(result: dict[str, Any], is_error: bool = False, text: str | None = None) -> types.CallToolResult:
    body = text if text is not None else json.dumps(result, ensure_ascii=False)
    return types.CallToolResult(content=[types.TextContent(type="text", text=body)],
                                structured_content=result, is_error=is_error)


def _error(message: str) -> types.CallToolResult:
    return types.CallToolResult(content=[types.TextContent(type="text", text=message)], is_error=True)


def episode_tool_definitions(settings: ServeSettings) -> list[types.Tool]:
    eid = {"type": "string", "description": f"The episode (or pass it in the request _meta as {EPISODE_META_KEY!r})."}
    return [
        types.Tool(name="start_episode", description=(
            "Start an episode of a task: returns its episode_id (name it in later calls) and the prompt parts "
            "(system, policy, ticket, tools) and first chat messages."),
            input_schema={"type": "object", "properties": {
                "domain": {"type": "string", "enum": list(settings.domains),
                           "description": f"The domain (default {settings.domains[0]!r})."},
                "task_id": {"type": "string", "description": "A task id; otherwise one is drawn from the split."},
                "split": {"type": "string", "description": f"Task split to draw from (default {settings.split!r})."},
                "seed": {"type": "integer", "description": "Seed of the draw."}}}),
        types.Tool(name="finish_episode", description=(
            "End the episode and return its score (reward, the 5 components, the end reason). final_text: a text "
            "answer, graded as the submitted answer; reason: a cut (e.g. 'token_limit'). Idempotent."),
            input_schema={"type": "object", "properties": {
                "episode_id": eid, "final_text": {"type": "string"},
                "reason": {"type": "string", "enum": [r for r in END_REASONS if r not in ("answer", "text_answer")]}}}),
        types.Tool(name="episode_result", description="The episode's state: running, or its score once ended.",
                   input_schema={"type": "object", "properties": {"episode_id": eid}}),
    ]


def build_server(settings: ServeSettings, store: EpisodeStore | None = None) -> tuple[Server, EpisodeStore]:
    """The MCP server (lowlevel API) over an episode store."""
    store = store or EpisodeStore(settings)
    schemas: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for domain in settings.domains:
        schemas[domain] = HealthcareGymEnv(domain=domain, split=None).tool_schemas
    episode_tools = episode_tool_definitions(settings)

    def domain_tools(domain: str) -> list[types.Tool]:
        return [types.Tool(name=s["function"]["name"], description=s["function"].get("description"),
                           input_schema=s["function"]["parameters"]) for s in schemas[domain]]

    def session_of(ctx: Any) -> str | None:
        request = getattr(ctx, "request", None)
        headers = getattr(request, "headers", None)
        return headers.get(SESSION_HEADER) if headers is not None else None

    def meta_of(ctx: Any, params: Any) -> dict[str, Any]:
        meta = getattr(params, "meta", None) or getattr(ctx, "meta", None) or {}
        return dict(meta) if isinstance(meta, dict) else dict(getattr(meta, "model_extra", None) or {})

    async def on_list_tools(ctx: Any, params: types.PaginatedRequestParams | None) -> types.ListToolsResult:
        # The tools of the named episode's domain; otherwise of the first served domain.
        domain = settings.domains[0]
        eid = meta_of(ctx, params).get(EPISODE_META_KEY)
        if isinstance(eid, str):
            try:
                domain = store.get(eid, None).domain
            except ToolCallError:
                pass
        return types.ListToolsResult(tools=[*episode_tools, *domain_tools(domain)])

    def run_call(name: str, arguments: dict[str, Any], meta: dict[str, Any], session_id: str | None
                 ) -> types.CallToolResult:
        if name == "start_episode":
            _, result = store.start(_parse(StartArgs, name, arguments), session_id)
            return _text(result)
        meta_eid = meta.get(EPISODE_META_KEY)
        if meta_eid is not None and not isinstance(meta_eid, str):
            raise ToolCallError(f"_meta {EPISODE_META_KEY!r} must be a string, got {type(meta_eid).__name__}")
        if name in ("finish_episode", "episode_result"):
            model = FinishArgs if name == "finish_episode" else ResultArgs
            parsed = _parse(model, name, arguments)
            episode = store.get(parsed.episode_id or meta_eid, session_id)
            with episode.lock:
                if episode.end is None and name == "finish_episode":
                    try:
                        end = episode.env.finish(final_text=parsed.final_text, reason=parsed.reason)
                    except ValueError as exc:
                        raise ToolCallError(f"finish_episode: argument 'reason': {exc}") from exc
                    store.ended(episode, end)
                if episode.end is None:
                    return _text({"episode_id": episode.id, "done": False, "task_id": episode.task_id})
                return _text({"episode_id": episode.id, "done": True, "task_id": episode.task_id,
                              "score": score_of(episode.end)})
        arguments = dict(arguments)
        arg_eid = arguments.pop("episode_id", None)
        if arg_eid is not None and not isinstance(arg_eid, str):
            raise ToolCallError(f"{name}: argument 'episode_id' must be a string, got {type(arg_eid).__name__}")
        episode = store.get(meta_eid or arg_eid, session_id)
        message = meta.get(MESSAGE_META_KEY, "")
        if not isinstance(message, str):
            raise ToolCallError(f"_meta {MESSAGE_META_KEY!r} must be a string, got {type(message).__name__}")
        if meta.get(SAME_TURN_META_KEY) is True:
            message = None
        with episode.lock:
            if episode.end is not None:
                return _text({"episode_id": episode.id, "done": True, "score": score_of(episode.end)},
                             is_error=True, text=f"The episode is over ({episode.end.reason}); start a new one.")
            result = episode.env.call_tool(name, arguments, message=message)
            payload: dict[str, Any] = {"episode_id": episode.id, "ok": result.ok, "done": result.done,
                                       "error": result.error, "error_kind": result.error_kind}
            text = result.observation
            if result.done and result.end is not None:
                store.ended(episode, result.end)
                payload["score"] = score_of(result.end)
                text = f"{text}\n\n[episode over: {json.dumps(payload['score'], ensure_ascii=False)}]"
            return _text(payload, is_error=not result.ok, text=text)

    async def on_call_tool(ctx: Any, params: types.CallToolRequestParams) -> types.CallToolResult:
        name = params.name
        if len(name) > MAX_TOOL_NAME_CHARS:
            return _error(f"unknown tool {shown(name)}: a tool name has at most {MAX_TOOL_NAME_CHARS} characters")
        arguments = params.arguments or {}
        try:
            size = len(json.dumps(arguments))
        except (TypeError, ValueError, RecursionError):
            return _error(f"{name}: arguments are not JSON (or nested too deeply)")
        if size > settings.max_argument_chars:
            return _error(f"{name}: arguments are {size} characters as JSON, over the server's limit of "
                          f"{settings.max_argument_chars} (--max-argument-chars)")
        try:
            return await anyio.to_thread.run_sync(run_call, name, arguments, meta_of(ctx, params), session_of(ctx))
        except ToolCallError as exc:
            return _error(str(exc))
        except Exception as exc:  # a fault in one call must not take the server down; the client sees it
            return _error(f"{name}: internal error: {type(exc).__name__}: {exc}")

    def input_schema(name: str) -> dict[str, Any] | None:
        for tool in episode_tools:
            if tool.name == name:
                return tool.input_schema
        for domain in settings.domains:
            for s in schemas[domain]:
                if s["function"]["name"] == name:
                    return s["function"]["parameters"]
        return None

    server = Server("healthcare-ai-gym", version="0.1.0", instructions=(
        "Call start_episode, then the task's tools naming the episode (request _meta "
        f"{EPISODE_META_KEY!r} or an episode_id argument); submit_answer or finish_episode ends it and "
        "returns the score."), on_list_tools=on_list_tools, on_call_tool=on_call_tool,
        get_tool_input_schema=input_schema)
    server.middleware.append(name_invalid_params)
    return server, store


async def name_invalid_params(ctx: Any, call_next: Any) -> Any:
    """Server middleware: request params that fail the SDK's validation (a tool name that is not a string,
    arguments that are not an object) get an error naming the field; the SDK's own says only "Invalid
    request parameters"."""
    try:
        return await call_next(ctx)
    except ValidationError as exc:
        problems = "; ".join(f"params.{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()[:3])
        raise MCPError(code=types.INVALID_PARAMS, message=f"Invalid request parameters: {problems}") from None


def _parse(model: type[BaseModel], tool: str, arguments: dict[str, Any]) -> Any:
    try:
        return model.model_validate(arguments)
    except ValidationError as exc:
        problems = "; ".join(f"argument {'.'.join(str(p) for p in e['loc']) or '(all)'!r}: {e['msg']}"
                             for e in exc.errors())
        raise ToolCallError(f"{tool}: {problems}") from None


def build_app(settings: ServeSettings) -> tuple[Any, EpisodeStore]:
    """The ASGI app (MCP at /mcp, behind the HTTP guard) and its episode store."""
    server, store = build_server(settings)
    # json_response: a call is answered as one JSON body, not an SSE stream. The server sends no
    # notifications during a call, and the stream cost a task group and SSE framing on both ends of
    # every call, more than half of a call's CPU on each side (docs/benchmarks.md, "Env server").
    app = server.streamable_http_app(host=settings.host, max_request_body_size=settings.max_request_bytes,
                                     session_idle_timeout=settings.idle_timeout_s, max_sessions=settings.max_sessions,
                                     json_response=True)
    if settings.token:
        app = BearerToken(app, settings.token)
    return HTTPGuard(app, max_requests=settings.max_requests, request_timeout_s=settings.request_timeout_s,
                     max_body_bytes=settings.max_request_bytes, busy_wait_s=settings.busy_wait_s), store


def uvicorn_server(settings: ServeSettings, app: Any) -> Any:
    """uvicorn serving `app` with the settings' connection bound and first-request deadline."""
    import uvicorn

    return uvicorn.Server(uvicorn.Config(
        app, host=settings.host, port=settings.port, http=guarded_protocol(settings.request_timeout_s),
        limit_concurrency=settings.max_connections, backlog=2048, timeout_keep_alive=5,
        h11_max_incomplete_event_size=H11_MAX_HEAD, log_level="warning"))


def serve(settings: ServeSettings, warmup: bool = True) -> None:
    if warmup:  # the first score of a process loads graders; pay that before the first client
        for domain in settings.domains:
            HealthcareGymEnv(domain=domain, split=settings.split).warmup()
    app, _ = build_app(settings)
    server = uvicorn_server(settings, app)
    sock = server.config.bind_socket()  # bound here so --port 0 prints the port it got
    sock.listen(server.config.backlog)  # clients that read the line below may connect before uvicorn starts
    host = f"[{settings.host}]" if ":" in settings.host else settings.host
    print(f"hcgym serve: MCP (streamable HTTP) at http://{host}:{sock.getsockname()[1]}/mcp "
          f"domains={','.join(settings.domains)}", flush=True)
    server.run(sockets=[sock])
