"""`HealthcareGymEnvironment`: an OpenEnv `Environment` over the env's one episode core.

One instance per OpenEnv session (one WebSocket, or one `/mcp` session). `reset` starts a task;
`step` takes OpenEnv's `ListToolsAction` (the episode tools and the task's tools, schemas verbatim)
and `CallToolAction` (a task tool through `HealthcareGymEnv.call_tool`, or an episode tool:
`start_episode`, `finish_episode` through `HealthcareGymEnv.finish`, `episode_result`), so an episode
scores the same here as in process. The call that ends an episode returns `done`, `reward` and, in
`metadata`, the reward's components and the whole score.

A tool's own failure (a lookup that found nothing, a range check) is its result, as the agent would
see it in process; a call the framework refuses (unknown tool, arguments that do not fit, over the
size limit, no episode, an episode already over) is a `ToolError`.
"""

from __future__ import annotations

import json
import uuid
from functools import lru_cache
from typing import Any

from openenv.core.env_server.interfaces import Environment
from pydantic import ValidationError

from envs.env import HealthcareGymEnv, render_ticket
from envs.episode import END_REASONS, EpisodeEnd, ToolResult
from envs.integrations.openenv.models import (MAX_TOOL_NAME_CHARS, MESSAGE_META_KEY, SAME_TURN_META_KEY, CallToolAction,
                                              CallToolObservation, FinishArgs, HealthcareGymObservation,
                                              HealthcareGymState, ListToolsAction, ListToolsObservation, ResetArgs,
                                              Tool, ToolError, ToolErrorType)
from envs.serve.settings import ServeSettings

_FRAMEWORK_ERRORS = {"unknown_tool": ToolErrorType.TOOL_NOT_FOUND, "invalid_arguments": ToolErrorType.INVALID_ARGS,
                     "internal_error": ToolErrorType.EXECUTION_ERROR, "episode_over": ToolErrorType.EXECUTION_ERROR}


def score_of(end: EpisodeEnd) -> dict[str, Any]:
    """The score a client sees: the `EpisodeEnd` without the episode record."""
    return end.model_dump(mode="json", exclude={"episode"})


@lru_cache(maxsize=None)
def _split_tasks(domains: tuple[str, ...], split: str) -> tuple[tuple[str, str], ...]:
    """(domain, task id) of every task of `split` over the served domains, in the task API's order."""
    from envs.registry import get_splits, get_tasks

    return tuple((d, t.id) for d in domains if split in get_splits(d) for t in get_tasks(d, split))


@lru_cache(maxsize=None)
def _tool_definitions(domain: str) -> tuple[Tool, ...]:
    schemas = HealthcareGymEnv(domain=domain, split=None).tool_schemas
    return tuple(Tool(name=s["function"]["name"], description=s["function"].get("description") or "",
                      input_schema=s["function"]["parameters"]) for s in schemas)


def episode_tool_definitions(settings: ServeSettings) -> list[Tool]:
    return [
        Tool(name="start_episode", description=(
            "Start an episode (what reset does, for a client that only calls tools): returns the episode "
            "and its prompt parts."), input_schema={"type": "object", "properties": {
                "domain": {"type": "string", "enum": list(settings.domains),
                           "description": f"The domain (default {settings.domains[0]!r})."},
                "task_id": {"type": "string", "description": "A task id; otherwise one is drawn from the split."},
                "split": {"type": "string", "description": f"Task split (default {settings.split!r})."},
                "index": {"type": "integer", "minimum": 0, "description": "The task's index in the split (task API)."},
                "seed": {"type": "integer", "description": "Seed of the draw."}}}),
        Tool(name="finish_episode", description=(
            "End the episode and return its score (reward, the 5 components, the end reason). final_text: a "
            "text answer, graded as the submitted answer; reason: a cut (e.g. 'token_limit'). Idempotent."),
            input_schema={"type": "object", "properties": {
                "final_text": {"type": "string"},
                "reason": {"type": "string",
                           "enum": [r for r in END_REASONS if r not in ("answer", "text_answer")]}}}),
        Tool(name="episode_result", description="The episode's state: running, or its score once ended.",
             input_schema={"type": "object", "properties": {}}),
    ]


class HealthcareGymEnvironment(Environment[CallToolAction, CallToolObservation, HealthcareGymState]):
    """One session's episodes of the served domains (`ServeSettings`: domains, default split, turn,
    call and result limits, the largest arguments)."""

    # Each instance builds its own HealthcareGymEnv, whose domain database is the episode's own copy.
    SUPPORTS_CONCURRENT_SESSIONS = True

    def __init__(self, settings: ServeSettings | None = None) -> None:
        super().__init__()
        # OpenEnv builds an instance per HTTP request too (task API, /metadata): nothing heavy here.
        self.settings = settings or ServeSettings()
        self._env: HealthcareGymEnv | None = None
        self._state = HealthcareGymState()
        self._closed = False

    # -- episodes -------------------------------------------------------------------------------
    def reset(self, seed: int | None = None, episode_id: str | None = None, **kwargs: Any) -> HealthcareGymObservation:
        self._check_open()
        try:
            args = ResetArgs.model_validate({**kwargs, "seed": seed, "episode_id": episode_id})
        except ValidationError as exc:
            raise ValueError("reset: " + _problems(exc)) from None
        return self._start(args)

    def _start(self, args: ResetArgs) -> HealthcareGymObservation:
        domain, task_id, split = self._pick(args)
        env = HealthcareGymEnv(domain=domain, split=split, max_turns=self.settings.max_turns,
                               max_tool_calls=self.settings.max_tool_calls,
                               max_tool_result_chars=self.settings.max_tool_result_chars)
        env.reset(seed=args.seed, options={"task_id": task_id} if task_id is not None else None)
        self._env = env
        self._state = HealthcareGymState(episode_id=args.episode_id or uuid.uuid4().hex, step_count=0,
                                         domain=domain, task_id=env.task.id, split=split)
        parts = env.prompt()
        return HealthcareGymObservation(
            episode_id=self._state.episode_id, domain=domain, task_id=env.task.id, split=split,
            prompt=parts.model_dump(), messages=parts.messages(), done=False, reward=None,
            metadata={"max_turns": env.max_turns, "max_tool_calls": env.max_tool_calls})

    def _pick(self, args: ResetArgs) -> tuple[str, str | None, str | None]:
        """(domain, task id or None to draw one, split) of a reset, every argument checked."""
        served = self.settings.domains
        if args.domain is not None and args.domain not in served:
            raise ValueError(f"reset: argument 'domain': {args.domain!r} is not served here (served: {', '.join(served)})")
        if args.index is not None:
            if args.task_id is not None:
                raise ValueError("reset: give 'task_id' or ('split', 'index'), not both")
            split = args.split if args.split is not None else self.settings.split
            tasks = _split_tasks(tuple(served), split) if split is not None else ()
            if args.index >= len(tasks):
                raise ValueError(f"reset: argument 'index': {args.index} is out of range: split {split!r} has "
                                 f"{len(tasks)} tasks over the served domains")
            domain, task_id = tasks[args.index]
            return domain, task_id, split
        if args.task_id is not None:
            from envs.registry import get_tasks

            for domain in ([args.domain] if args.domain else served):
                if any(t.id == args.task_id for t in get_tasks(domain, args.split)):
                    return domain, args.task_id, args.split
            raise ValueError(f"reset: argument 'task_id': no task {args.task_id!r} in "
                             f"{args.domain or ', '.join(served)}" + (f" split {args.split!r}" if args.split else ""))
        domain = args.domain or served[0]
        split = args.split if args.split is not None else self.settings.split
        from envs.registry import get_splits

        if split is not None and split not in get_splits(domain):
            raise ValueError(f"reset: argument 'split': domain {domain!r} has no split {split!r} "
                             f"(splits: {', '.join(get_splits(domain))})")
        return domain, None, split

    def step(self, action: Any, timeout_s: float | None = None, **kwargs: Any) -> Any:
        self._check_open()
        if isinstance(action, ListToolsAction):
            domain = self._state.domain or self.settings.domains[0]
            return ListToolsObservation(tools=[*episode_tool_definitions(self.settings), *_tool_definitions(domain)],
                                        done=self._state.done, reward=self._state.reward)
        if not isinstance(action, CallToolAction):
            raise ValueError(f"step: the action must be a CallToolAction or ListToolsAction, got {type(action).__name__}")
        self._state.step_count += 1
        name, arguments = action.tool_name, action.arguments
        if len(name) > MAX_TOOL_NAME_CHARS:
            return self._refused(name[:40] + "...", ToolErrorType.TOOL_NOT_FOUND,
                                 f"a tool name of {len(name)} characters, over {MAX_TOOL_NAME_CHARS}")
        size = len(json.dumps(arguments, ensure_ascii=False, default=str))
        if size > self.settings.max_argument_chars:
            return self._refused(name, ToolErrorType.INVALID_ARGS, (
                f"{name}: arguments are {size} characters as JSON, over the server's limit of "
                f"{self.settings.max_argument_chars} (--max-argument-chars)"))
        if name == "start_episode":
            try:
                started = self._start(ResetArgs.model_validate(arguments))
            except ValidationError as exc:
                return self._refused(name, ToolErrorType.INVALID_ARGS, f"{name}: {_problems(exc)}")
            except ValueError as exc:
                return self._refused(name, ToolErrorType.INVALID_ARGS, str(exc).replace("reset:", f"{name}:", 1))
            return CallToolObservation(tool_name=name, result=started.model_dump(exclude={"done", "reward"}),
                                       done=False, reward=None, metadata=self._meta())
        if self._env is None:
            return self._refused(name, ToolErrorType.EXECUTION_ERROR,
                                 f"{name}: no episode: reset first (or call start_episode)")
        if name == "finish_episode":
            try:
                parsed = FinishArgs.model_validate(arguments)
                end = self._env.finish(final_text=parsed.final_text, reason=parsed.reason)
            except ValidationError as exc:
                return self._refused(name, ToolErrorType.INVALID_ARGS, f"{name}: {_problems(exc)}")
            except ValueError as exc:
                return self._refused(name, ToolErrorType.INVALID_ARGS, f"{name}: argument 'reason': {exc}")
            return self._ended(name, end, result=score_of(end))
        if name == "episode_result":
            if arguments:
                return self._refused(name, ToolErrorType.INVALID_ARGS,
                                     f"{name}: takes no arguments, got {', '.join(map(repr, arguments))}")
            end = self._env.end
            if end is None:
                return CallToolObservation(tool_name=name, result={"done": False, "task_id": self._state.task_id},
                                           metadata=self._meta())
            return self._ended(name, end, result={"done": True, "score": score_of(end)})
        message = action.metadata.get(MESSAGE_META_KEY, "")
        if not isinstance(message, str):
            return self._refused(name, ToolErrorType.INVALID_ARGS,
                                 f"metadata {MESSAGE_META_KEY!r} must be a string, got {type(message).__name__}")
        if action.metadata.get(SAME_TURN_META_KEY) is True:
            message = None
        if self._env.end is not None:  # nothing runs after the end; the score stays readable
            refused = self._refused(name, ToolErrorType.EXECUTION_ERROR, (
                f"{name}: the episode is over ({self._env.end.reason}); reset (or start_episode) for a new one"))
            refused.metadata["score"] = score_of(self._env.end)
            return refused
        result = self._env.call_tool(name, arguments, message=message)
        return self._tool_observation(result)

    def _tool_observation(self, result: ToolResult) -> CallToolObservation:
        name = result.name
        kind = _FRAMEWORK_ERRORS.get(result.error_kind or "")
        if result.done and result.end is not None:  # this call ended it (an answer or a limit)
            return self._ended(name, result.end, result=result.observation, ok=result.ok)
        if kind is not None:
            return self._refused(name, kind, result.error or result.observation)
        return CallToolObservation(tool_name=name, result=result.observation, done=False, reward=None,
                                   metadata={**self._meta(), "ok": result.ok, "error": result.error,
                                             "error_kind": result.error_kind})

    def _ended(self, name: str, end: EpisodeEnd, result: Any, ok: bool = True) -> CallToolObservation:
        self._state.done, self._state.reward = True, end.reward
        self._state.reward_components, self._state.end_reason = dict(end.reward_components), end.reason
        return CallToolObservation(tool_name=name, result=result, done=True, reward=end.reward, metadata={
            **self._meta(), "ok": ok, "reward_components": dict(end.reward_components), "score": score_of(end)})

    def _refused(self, name: str, kind: ToolErrorType, message: str) -> CallToolObservation:
        return CallToolObservation(tool_name=name, error=ToolError(error_type=kind, message=message),
                                   done=self._state.done, reward=self._state.reward,
                                   metadata={**self._meta(), "ok": False})

    def _meta(self) -> dict[str, Any]:
        return {"episode_id": self._state.episode_id, "task_id": self._state.task_id, "domain": self._state.domain}

    @property
    def state(self) -> HealthcareGymState:
        return self._state

    def close(self) -> None:
        # OpenEnv closes a session's instance when its socket closes or when it sat idle past the
        # server's idle timeout; a socket still open then learns why on its next message.
        self._closed, self._env = True, None

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"this session is closed: it was idle for more than {self.settings.idle_timeout_s:g} s "
                               "(the server's --idle-timeout) or the server closed it; open a new session")

    # -- the task API (OpenEnv's TaskProvider) ---------------------------------------------------
    def list_splits(self) -> list[str]:
        from envs.registry import get_splits

        return list(dict.fromkeys(s for d in self.settings.domains for s in get_splits(d)))

    def list_tasks(self, split: str) -> list[dict[str, Any]]:
        """Every task of `split` over the served domains (an unknown split has none)."""
        return [{"index": i, "id": tid, "domain": d, "split": split}
                for i, (d, tid) in enumerate(_split_tasks(tuple(self.settings.domains), split))]

    def num_tasks(self, split: str) -> int:
        return len(_split_tasks(tuple(self.settings.domains), split))

    def get_task(self, split: str, index: int) -> dict[str, Any]:
        """The task at `index` of `split` with its ticket (`reset(split=..., index=...)` starts it); an
        index out of range raises IndexError (OpenEnv answers 400)."""
        from envs.registry import get_tasks

        tasks = _split_tasks(tuple(self.settings.domains), split)
        if not 0 <= index < len(tasks):
            raise IndexError(f"split {split!r} has {len(tasks)} tasks; no index {index}")
        domain, task_id = tasks[index]
        task = next(t for t in get_tasks(domain, split) if t.id == task_id)
        return {"index": index, "id": task_id, "domain": domain, "split": split, "ticket": render_ticket(task)}


def _problems(exc: ValidationError) -> str:
    return "; ".join(f"argument {'.'.join(str(p) for p in e['loc']) or '(all)'!r}: {e['msg']}" for e in exc.errors())
