"""`HealthcareGymEnv`: one clinical task per episode, tool calls as actions, the 5D reward at the end.

Example:
    >>> import gymnasium, envs
    >>> env = gymnasium.make("HealthcareGym-v0", domain="drug_interaction", split="test")
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(
    ...     '<tool_call>{"name": "think", "arguments": {"thought": "check the list"}}</tool_call>')
"""

from __future__ import annotations

import json
import math
import re
import time
from typing import Any, Callable, SupportsFloat

import gymnasium as gym

from envs.core.actions import parse_action
from envs.core.domain import DomainEnvironment
from envs.core.spaces import AnyText
from envs.core.task import Task
from envs.core.tools import ToolOutcome, safe_repr
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord
from envs.episode import (ANSWER_REASONS, END_REASONS, EndReason, EpisodeEnd, PromptParts, ToolResult, end_reason,
                           episode_record, safety_violations)

MAX_ACTION_CHARS = 100_000
MAX_OBSERVATION_CHARS = 1_000_000
MAX_TOOL_RESULT_CHARS = 50_000
# Tool calls executed per action; the rest are refused with an error observation. A real turn
# needs a handful of calls; without a cap one 99 KB action of 3,300 unknown-drug lookups took ~40 s.
MAX_CALLS_PER_ACTION = 32
# Wall-clock seconds one action's tool calls may take. Checked before each call (a running call is
# never interrupted): once spent, the action's remaining calls are refused with an error
# observation, except a submit, so the episode still ends (and is scored) when the agent answered.
# Sized far above any real action (32 warm calls take well under a second; a knowledge index's
# first load a few seconds), so it only cuts actions built to be slow. None disables it.
STEP_TIME_BUDGET_S = 10.0

CALL_FORMAT_HELP = (
    "To call a tool, write <tool_call>{\"name\": \"<tool>\", \"arguments\": {...}}</tool_call> "
    "(one block per call; several calls run in order). When you are done, call submit_answer."
)
# The observation of a turn that ended the episode as a text answer (`text_turn_ends_episode`).
TEXT_ANSWER_OBSERVATION = "Your message had no tool call, so it was taken as your final answer."
#: `info["end_reason"]` / `Trajectory.metadata["end_reason"]` of an episode ended that way.
TEXT_ANSWER_END_REASON: EndReason = "text_answer"
_THINK_BLOCK = re.compile(r"<think>.*?</think>", re.DOTALL)


def text_answer(message: str) -> str:
    """The final answer of a text turn: the message without its `<think>` blocks (reasoning is not
    the answer, as chat templates drop it from the assistant's content), stripped."""
    return _THINK_BLOCK.sub("", message).strip()


def render_ticket(task: Task) -> str:
    """The user-facing task text: the ticket, plus the options of a choice question."""
    text = task.ticket.strip()
    if task.options and not all(f"{k}." in text or f"({k})" in text for k in task.options):
        text += "\n\nOptions:\n" + "\n".join(f"{k}. {v}" for k, v in task.options.items())
    if task.patient_id and task.patient_id not in text:
        text += f"\n\nPatient ID: {task.patient_id}"
    return text


_PROMPT_CACHE: dict[tuple, str] = {}


def build_system_prompt(domain: DomainEnvironment) -> str:
    # Tool schemas are fixed per toolkit class, so the rendered prompt is cached by policy and the
    # toolkit's tool definitions (serialising ~30 schemas on every reset cost milliseconds).
    definitions = domain.toolkit.definitions
    key = (domain.name, domain.policy, tuple(id(d) for d in definitions.values()))
    prompt = _PROMPT_CACHE.get(key)
    if prompt is None:
        tools = "\n".join(json.dumps(d.openai_schema(), ensure_ascii=False) for d in definitions.values())
        prompt = f"{domain.policy}\n\n# Tools\n{CALL_FORMAT_HELP}\n<tools>\n{tools}\n</tools>"
        if len(_PROMPT_CACHE) > 256:
            _PROMPT_CACHE.clear()
        _PROMPT_CACHE[key] = prompt
    return prompt


def prompt_parts(domain: DomainEnvironment, task: Task) -> dict[str, Any]:
    """What an episode's prompt is made of, exactly as `reset` returns it in `info`: the system
    prompt, the tool schemas and the ticket. Agent runners render their chat prompt from these;
    code that needs a prompt without running an episode (length filters, corpora) calls this."""
    return {"system_prompt": build_system_prompt(domain), "tools": domain.toolkit.schemas(),
            "ticket": render_ticket(task)}


def call_as_text(name: str, arguments: Any) -> str:
    """A tool call in the env's text format (`<tool_call>{...}</tool_call>`), exactly as `step` parses it."""
    return "<tool_call>" + json.dumps({"name": name, "arguments": arguments}, ensure_ascii=False) + "</tool_call>"


def _positive_int_or_none(name: str, value: Any) -> int | None:
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
        raise ValueError(f"{name} must be a positive integer or None, got {value!r}")
    return value


class HealthcareGymEnv(gym.Env[str, str]):
    """A Gymnasium environment over one clinical domain.

    Two ways to act, one episode core: `step(text)` (the Gymnasium API: the text is parsed into tool
    calls, which run, and the episode ends on a submit, a text answer or a limit) and the structured
    API `call_tool(name, arguments, message)` / `finish(final_text, reason)` for agents whose
    framework parses calls itself. Both record the same turns and score with the same scorer; the
    end is an `envs.episode.EpisodeEnd` (`env.end`, `info["end"]`) with an `EndReason`.

    Args:
        domain: Registered domain name (see `envs.registry.list_domains()`).
        task_id: Fix the task; otherwise each reset samples one from the split with the env's RNG.
        split: Task split ("train", "test", ...); None for all tasks of the domain.
        max_turns: Assistant turns before the episode is truncated (end reason "turn_limit").
        render_mode: "ansi" (render returns the transcript) or "human" (prints it).
        reward_weights: Optional weights for the 5D reward (`envs.rewards.RewardWeights` fields).
        step_time_budget_s: Seconds an action's tool calls may take before the rest are refused
            (`STEP_TIME_BUDGET_S`); None for no budget.
        text_turn_ends_episode: End the episode at a turn whose action holds no tool call and no
            parse error: its text (without `<think>` blocks) is the submitted answer, graded as one,
            and `info["end_reason"]` / the record's `metadata["end_reason"]` is "text_answer". The
            usual chat-agent convention (OpenAI-style tool loops, TRL's tools mode end at the first
            reply without a tool call). Off by default: the env answers such a turn with a reminder
            of the call format and the episode goes on to `submit_answer` or `max_turns`.
        max_tool_calls: Tool calls (over the episode) before it is truncated (end reason
            "tool_call_limit"); calls of a `step` past the limit are refused. None: no limit.
        max_tool_result_chars: A tool result longer than this many characters is cut, with a marker
            (`MAX_TOOL_RESULT_CHARS`); None keeps it whole.

    Attributes:
        clock: The monotonic clock the step budget reads (`time.perf_counter`); tests inject one.
    """

    metadata = {"render_modes": ["ansi", "human"]}

    def __init__(self, domain: str = "drug_interaction", task_id: str | None = None, split: str | None = None,
                 max_turns: int = 10, render_mode: str | None = None,
                 reward_weights: dict[str, float] | None = None,
                 step_time_budget_s: float | None = STEP_TIME_BUDGET_S,
                 text_turn_ends_episode: bool = False, max_tool_calls: int | None = None,
                 max_tool_result_chars: int | None = MAX_TOOL_RESULT_CHARS) -> None:
        from envs import registry

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        if isinstance(max_turns, bool) or not isinstance(max_turns, int) or max_turns < 1:
            raise ValueError(f"max_turns must be a positive integer, got {max_turns!r}")
        if step_time_budget_s is not None and (
                isinstance(step_time_budget_s, bool) or not isinstance(step_time_budget_s, (int, float))
                or not math.isfinite(step_time_budget_s) or step_time_budget_s < 0):
            raise ValueError(f"step_time_budget_s must be a finite number of seconds >= 0 or None, "
                             f"got {step_time_budget_s!r}")
        if not isinstance(text_turn_ends_episode, bool):
            raise ValueError(f"text_turn_ends_episode must be true or false, got {text_turn_ends_episode!r}")
        self.max_tool_calls = _positive_int_or_none("max_tool_calls", max_tool_calls)
        self.max_tool_result_chars = _positive_int_or_none("max_tool_result_chars", max_tool_result_chars)
        self.text_turn_ends_episode = text_turn_ends_episode
        self.step_time_budget_s = None if step_time_budget_s is None else float(step_time_budget_s)
        self.clock: Callable[[], float] = time.perf_counter
        self.domain_name = domain
        self.split = split
        self.max_turns = max_turns
        self.render_mode = render_mode
        self.reward_weights = reward_weights
        self.tasks: list[Task] = registry.get_tasks(domain, split)
        if not self.tasks:
            raise ValueError(f"domain {domain!r} has no tasks in split {split!r}")
        self._tasks_by_id = {t.id: t for t in self.tasks}
        if task_id is not None and task_id not in self._tasks_by_id:
            raise KeyError(f"task {task_id!r} is not in domain {domain!r} split {split!r}")
        self.task_id = task_id
        self._registry = registry
        self.observation_space = AnyText(MAX_OBSERVATION_CHARS)
        self.action_space = AnyText(MAX_ACTION_CHARS)
        self.domain_env: DomainEnvironment | None = None
        self.task: Task | None = None
        self._record: Trajectory | None = None
        self._done = False
        self._end: EpisodeEnd | None = None
        self._tool_calls_run = 0
        # The turn `call_tool` is adding calls to (None: the next call opens a new turn), with the
        # observation text of each of its calls and its assistant chat message.
        self._call_turn: TurnRecord | None = None
        self._call_turn_texts: list[str] = []
        self._call_turn_message: dict[str, Any] | None = None

    # -- Gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[str, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        task_id = options.get("task_id", self.task_id)
        if task_id is not None:
            if task_id not in self._tasks_by_id:
                raise KeyError(f"task {task_id!r} is not in domain {self.domain_name!r} split {self.split!r}")
            task = self._tasks_by_id[task_id]
        else:
            task = self.tasks[int(self.np_random.integers(len(self.tasks)))]
        self.task = task
        self.domain_env = self._registry.get_environment(self.domain_name)
        if self.domain_env.on_reset is not None:
            self.domain_env.on_reset(self.domain_env, task)
        parts = prompt_parts(self.domain_env, task)
        system_prompt, ticket = parts["system_prompt"], parts["ticket"]
        observation = f"{system_prompt}\n\n# Task\n{ticket}"
        user_content: str | list[dict[str, str]] = ticket
        if task.image_path:
            # Multimodal policies get the image as a content part (chat templates that support images
            # render it); text-only policies see the path in the observation.
            observation += f"\n\n[image: {task.image_path}]"
            user_content = [{"type": "image", "image": task.image_path}, {"type": "text", "text": ticket}]
        self._record = Trajectory(
            task_id=task.id, domain=self.domain_name, seed=seed, system_prompt=system_prompt,
            first_observation=observation, image_path=task.image_path,
            messages=[{"role": "system", "content": system_prompt}, {"role": "user", "content": user_content}],
            # Hashing a whole database costs milliseconds; only tasks graded on state need the start hash.
            db_hash_initial=self.domain_env.db_hash() if "DB" in task.evaluation_criteria.reward_basis else None,
        )
        self._done = False
        self._end = None
        self._tool_calls_run = 0
        self._close_call_turn()
        info = {
            "task_id": task.id, "domain": self.domain_name, "tools": parts["tools"],
            "policy": self.domain_env.policy, "max_turns": self.max_turns, "system_prompt": system_prompt,
            "ticket": ticket, "image_path": task.image_path,
        }
        return observation, info

    def step(self, action: str) -> tuple[str, SupportsFloat, bool, bool, dict[str, Any]]:
        if self._record is None or self.domain_env is None or self.task is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            return "The episode is over; call reset() to start a new one.", 0.0, True, False, {"error": "episode_over"}
        self._close_call_turn()
        started = time.perf_counter()
        budget_start = self.clock()
        turn_index = len(self._record.turns)
        toolkit = self.domain_env.toolkit
        if isinstance(action, str) and len(action) > MAX_ACTION_CHARS:
            parsed = parse_action("")
            parsed.errors.append(f"action of {len(action)} characters exceeds the limit of {MAX_ACTION_CHARS}")
            parsed.format = "text"
            raw = action[:MAX_ACTION_CHARS]
        else:
            parsed = parse_action(action, toolkit.definitions)
            raw = action if isinstance(action, str) else safe_repr(action, 2000)
        records: list[ToolCallRecord] = []
        parts: list[str] = []
        submitted: str | None = None
        refusal: str | None = None
        if len(parsed.calls) > MAX_CALLS_PER_ACTION:
            refusal = (f"{len(parsed.calls) - MAX_CALLS_PER_ACTION} tool calls after the first {MAX_CALLS_PER_ACTION} "
                       f"were not run: an action may make at most {MAX_CALLS_PER_ACTION} calls")
            parsed.calls = parsed.calls[:MAX_CALLS_PER_ACTION]
        over_budget: list[str] = []  # calls refused because the step's time budget was spent
        over_limit = 0  # calls refused because the episode's tool-call limit was reached
        for call in parsed.calls:
            if self._budget_spent(budget_start) and not self._is_submit(call.name):
                over_budget.append(call.name if isinstance(call.name, str) else safe_repr(call.name, 80))
                continue
            if self._call_limit_reached():
                over_limit += 1
                continue
            record, text, answer = self._run_call(call.name, call.arguments, call.format)
            records.append(record)
            parts.append(text if len(parsed.calls) == 1 else f"[{record.name}] {text}")
            if answer is not None:
                submitted = answer
                break
        for error in parsed.errors:
            parts.append(json.dumps({"error": f"could not parse action: {error}"}))
        if refusal is not None:
            parts.append(json.dumps({"error": refusal}))
            parsed.errors.append(refusal)  # recorded with the turn's parse errors
        if over_budget:
            shown = ", ".join(over_budget[:8]) + (", ..." if len(over_budget) > 8 else "")
            budget_refusal = (f"{len(over_budget)} tool calls ({shown}) were not run: this action's tool calls "
                              f"took longer than the step time budget of {self.step_time_budget_s:g} s")
            parts.append(json.dumps({"error": budget_refusal}))
            parsed.errors.append(budget_refusal)
        if over_limit:
            limit_refusal = (f"{over_limit} tool calls were not run: the episode's limit of {self.max_tool_calls} "
                             f"tool calls is reached")
            parts.append(json.dumps({"error": limit_refusal}))
            parsed.errors.append(limit_refusal)
        # A turn with neither a call nor a parse error is plain text: the final answer when
        # `text_turn_ends_episode`, else a reminder of the call format. A malformed call (a parse
        # error) never ends the episode: the agent meant to call a tool and sees why it failed.
        text_turn = not parsed.calls and not parsed.errors
        if text_turn and self.text_turn_ends_episode:
            submitted = text_answer(parsed.message)
            parts.append(TEXT_ANSWER_OBSERVATION)
        elif text_turn:
            parts.append("No tool call found in your message. " + CALL_FORMAT_HELP)
        ended_by_text = text_turn and self.text_turn_ends_episode
        observation = "\n".join(parts)[:MAX_OBSERVATION_CHARS]
        turn = TurnRecord(index=turn_index, action=raw, message=parsed.message, action_format=parsed.format,
                          tool_calls=records, parse_errors=parsed.errors, observation=observation,
                          duration_s=time.perf_counter() - started)
        self._record.turns.append(turn)
        self._record.messages.append(_assistant_message(raw, records))
        for rec in records:
            self._record.messages.append({"role": "tool", "name": rec.name,
                                          "content": rec.result if rec.ok else json.dumps({"error": rec.error})})
        if not records and not ended_by_text:  # the episode is over: no one answers a text answer
            self._record.messages.append({"role": "user", "content": observation})

        info: dict[str, Any] = {"turn": turn_index, "tool_calls": [r.name for r in records],
                                "action_format": parsed.format, "parse_errors": parsed.errors,
                                # kinds of the calls that failed (unknown_tool, invalid_arguments, ...)
                                "tool_errors": [r.error_kind for r in records if r.error_kind]}
        if over_budget:
            info["calls_over_budget"] = len(over_budget)
        reason: EndReason | None = None
        if submitted is not None:
            reason = TEXT_ANSWER_END_REASON if ended_by_text else "answer"
        elif len(self._record.turns) >= self.max_turns:
            reason = "turn_limit"
        elif self._call_limit_reached():
            reason = "tool_call_limit"
        reward = 0.0
        if reason is not None:
            reward = self._end_episode(reason, submitted, info).reward
        if self.render_mode == "human":
            print(self._render_turn(turn))
        return observation, reward, reason in ANSWER_REASONS, reason is not None and reason not in ANSWER_REASONS, info

    # -- the structured API ----------------------------------------------------------------------
    @property
    def tool_schemas(self) -> list[dict[str, Any]]:
        """The domain's tool schemas (OpenAI function format), in the toolkit's stable order: domain
        tools first, then shared ones, as the system prompt lists them. Available before `reset`."""
        domain_env = self.domain_env or self._schema_env()
        return domain_env.toolkit.schemas()

    def _schema_env(self) -> DomainEnvironment:
        if getattr(self, "_schema_domain_env", None) is None:
            self._schema_domain_env = self._registry.get_environment(self.domain_name)
        return self._schema_domain_env

    def prompt(self) -> PromptParts:
        """The running episode's prompt parts: the system message without the tool block, the
        policy, the ticket, the tool schemas and the image (`envs.episode.PromptParts`)."""
        if self.domain_env is None or self.task is None:
            raise RuntimeError("call reset() before prompt()")
        parts = prompt_parts(self.domain_env, self.task)
        return PromptParts(system=self.domain_env.policy, policy=self.domain_env.policy, ticket=parts["ticket"],
                           tools=parts["tools"], image_path=self.task.image_path,
                           system_prompt=parts["system_prompt"])

    @property
    def done(self) -> bool:
        """The episode is over (answered, cut, or never started)."""
        return self._done or self._record is None

    @property
    def end(self) -> EpisodeEnd | None:
        """How the episode ended and its score; None while it runs."""
        return self._end

    @property
    def reward(self) -> float | None:
        """The episode's reward once it ended; None while it runs."""
        return None if self._end is None else self._end.reward

    @property
    def reward_components(self) -> dict[str, float] | None:
        """The 5D reward's components (and `total`) once the episode ended; None while it runs."""
        return None if self._end is None else dict(self._end.reward_components)

    def call_tool(self, name: str, arguments: dict[str, Any] | str | None = None,
                  message: str | None = None) -> ToolResult:
        """Run one tool call of the running episode.

        The calls of one assistant turn are recorded as one turn, as `step` records an action: a
        call with `message` (the turn's free text, "" for none) opens a new turn, a call without it
        joins the open one (the episode's first call opens the first). Opening a turn past
        `max_turns` runs nothing and ends the episode ("turn_limit"), scored as `step` scores it;
        so does `end_turn()` at the limit. A successful submit call ends it ("answer"), and the call
        that reaches `max_tool_calls` ends it ("tool_call_limit"). The step time budget applies to
        `step` actions only: a single call is never interrupted.

        Args:
            name: The tool's name.
            arguments: Its arguments: a dict, or a JSON object as text (OpenAI's wire form); None
                for none.
            message: The assistant turn's free text; starts a new turn when given.

        Returns:
            A `ToolResult`: the observation, ok, the error and its kind, and the episode's end when
            this call ended it. A call after the end returns `error_kind="episode_over"`; never raises
            for a bad name or arguments.
        """
        if self._record is None or self.domain_env is None or self.task is None:
            raise RuntimeError("call reset() before call_tool()")
        shown_name = name if isinstance(name, str) else safe_repr(name, 80)
        if self._done:
            return ToolResult(name=shown_name, observation="The episode is over; call reset() to start a new one.",
                              ok=False, error="the episode is over", error_kind="episode_over", done=True,
                              end=self._end)
        if isinstance(arguments, str):
            try:
                arguments = json.loads(arguments) if arguments.strip() else {}
            except json.JSONDecodeError:
                pass  # passed on as text: the toolkit refuses it as invalid arguments
        elif arguments is None:
            arguments = {}
        if message is not None or self._call_turn is None:
            self._close_call_turn()
            if len(self._record.turns) >= self.max_turns:
                end = self._end_episode("turn_limit", None, {})
                return ToolResult(name=shown_name, observation=f"The episode is over: the limit of {self.max_turns} "
                                  "assistant turns is reached; the call was not run.", ok=False,
                                  error="the turn limit is reached", error_kind="episode_over", done=True, end=end)
            self._open_call_turn(message or "")
        turn = self._call_turn
        assert turn is not None and self._call_turn_message is not None
        started = time.perf_counter()
        record, text, answer = self._run_call(name, arguments, "openai")
        turn.tool_calls.append(record)
        self._call_turn_texts.append(text)
        calls = turn.tool_calls
        turn.observation = "\n".join(
            t if len(calls) == 1 else f"[{c.name}] {t}" for c, t in zip(calls, self._call_turn_texts))[:MAX_OBSERVATION_CHARS]
        turn.action = "\n".join(([turn.message] if turn.message else [])
                                + [call_as_text(c.name, c.arguments) for c in calls])
        turn.duration_s += time.perf_counter() - started
        self._call_turn_message.setdefault("tool_calls", []).append(
            {"type": "function", "function": {"name": record.name,
                                              "arguments": json.dumps(record.arguments, ensure_ascii=False)}})
        self._record.messages.append({"role": "tool", "name": record.name,
                                      "content": record.result if record.ok else json.dumps({"error": record.error})})
        end = None
        if answer is not None:
            end = self._end_episode("answer", answer, {})
        elif self._call_limit_reached():
            end = self._end_episode("tool_call_limit", None, {})
        return ToolResult(name=record.name, arguments=record.arguments, observation=text, ok=record.ok,
                          error=record.error, error_kind=record.error_kind, submit=record.submit,
                          done=end is not None, end=end)

    def end_turn(self) -> EpisodeEnd | None:
        """Close the turn `call_tool` is adding calls to; at `max_turns` turns the episode ends here
        ("turn_limit"), as `step` ends it after its last allowed turn. Returns the end, if any."""
        if self._record is None:
            raise RuntimeError("call reset() before end_turn()")
        self._close_call_turn()
        if not self._done and len(self._record.turns) >= self.max_turns:
            return self._end_episode("turn_limit", None, {})
        return self._end

    def finish(self, final_text: str | None = None, reason: EndReason | str | None = None) -> EpisodeEnd:
        """End the running episode and score it; idempotent (once over, returns the same end).

        Args:
            final_text: The agent's final text answer (a chat reply without a tool call): recorded
                as one more turn and graded exactly as `submit_answer` with that text (its
                `<think>` blocks left out), end reason "text_answer". Past `max_turns` it is not
                graded: the episode is cut at the turn limit instead ("turn_limit").
            reason: Without `final_text`, why the runner cuts the episode (an `EndReason` other
                than "answer"/"text_answer", e.g. "token_limit"); scored by the domain's own scorer
                exactly as a turn-limit truncation.

        Returns:
            The `EpisodeEnd`.
        """
        if self._record is None or self.domain_env is None or self.task is None:
            raise RuntimeError("call reset() before finish()")
        if self._end is not None:
            return self._end
        if final_text is not None:
            if not isinstance(final_text, str):
                raise ValueError(f"final_text must be a string, got {type(final_text).__name__}")
            if reason is not None and reason != TEXT_ANSWER_END_REASON:
                raise ValueError(f"finish(final_text=...) ends with reason 'text_answer', not {reason!r}")
            self._close_call_turn()
            if len(self._record.turns) >= self.max_turns:
                return self._end_episode("turn_limit", None, {})
            raw = final_text[:MAX_ACTION_CHARS]
            message = raw.strip()
            self._record.turns.append(TurnRecord(index=len(self._record.turns), action=raw, message=message,
                                                 action_format="text" if message else "empty",
                                                 observation=TEXT_ANSWER_OBSERVATION))
            self._record.messages.append(_assistant_message(raw, []))
            return self._end_episode(TEXT_ANSWER_END_REASON, text_answer(message), {})
        if reason is None:
            raise ValueError("finish() needs final_text (a text answer) or reason (why the episode is cut)")
        cut = end_reason(reason)
        if cut in ANSWER_REASONS:
            raise ValueError(f"finish(reason={reason!r}): an answer ends the episode through the submit tool or "
                             f"final_text; reason names a cut: one of "
                             f"{', '.join(r for r in END_REASONS if r not in ANSWER_REASONS)}")
        self._close_call_turn()
        return self._end_episode(cut, None, {})

    def truncate(self, reason: str) -> tuple[float, dict[str, Any]]:
        """End the running episode from outside the env (an agent runner's token or context limit),
        scored exactly as a turn-limit truncation: by the domain's own scorer. `finish(reason=...)`
        in the older (reward, info) form; unlike `finish`, it refuses an episode that is over.

        Args:
            reason: Why the runner stopped: an `EndReason` (e.g. "token_limit").

        Returns:
            (reward, info) with the same reward keys as the terminal `step`'s info, the end reason in
            `info["end_reason"]` and the `EpisodeEnd` in `info["end"]`.
        """
        if self._record is None:
            raise RuntimeError("call reset() before truncate()")
        if self._done:
            raise RuntimeError(f"episode of task {self._record.task_id!r} is already over")
        cut = end_reason(reason)
        if cut in ANSWER_REASONS:
            raise ValueError(f"truncate({reason!r}): an answer is not a truncation")
        self._close_call_turn()
        info: dict[str, Any] = {"end_reason": cut}
        end = self._end_episode(cut, None, info)
        return end.reward, info

    def warmup(self) -> float:
        """Load what the first score of a process would load (the graders, the reward's lexicons and
        models), by scoring one throwaway episode of this domain; the running episode is untouched.
        Returns the seconds it took."""
        from envs.rewards import score_episode

        started = time.perf_counter()
        domain_env = self._registry.get_environment(self.domain_name)
        task = self.tasks[0]
        submit = ToolCallRecord(name="submit_answer", arguments={"answer": task.correct_answer or ""},
                                format="json", submit=True, result="submitted")
        record = Trajectory(task_id=task.id, domain=self.domain_name, submitted_answer=task.correct_answer or "",
                            terminated=True, turns=[TurnRecord(index=0, action="", action_format="json",
                                                               tool_calls=[submit])])
        record.db_hash_final = domain_env.db_hash()
        (domain_env.scorer or score_episode)(record, task, self.reward_weights, domain_env.safety_context)
        return time.perf_counter() - started

    # -- the core both APIs share ----------------------------------------------------------------
    def _run_call(self, name: Any, arguments: Any, fmt: str) -> tuple[ToolCallRecord, str, str | None]:
        """Run one call: (its record, the observation text, the answer when it was an accepted submit)."""
        assert self.domain_env is not None
        call_start = time.perf_counter()
        outcome: ToolOutcome = self.domain_env.toolkit.call(name, arguments)
        text = outcome.as_text()
        cap = self.max_tool_result_chars
        if cap is not None and len(text) > cap:
            text = text[:cap] + f"\n[truncated: result longer than {cap} characters]"
        self._tool_calls_run += 1
        record = ToolCallRecord(
            name=outcome.name, arguments=outcome.arguments, result=text if outcome.ok else None,
            error=outcome.error, error_kind=outcome.error_kind,
            tool_type=str(outcome.tool_type) if outcome.tool_type else None,
            format=fmt, submit=outcome.submit, duration_s=time.perf_counter() - call_start,
        )
        answer = str(outcome.arguments.get("answer", "")) if outcome.submit and outcome.ok else None
        return record, text, answer

    def _call_limit_reached(self) -> bool:
        return self.max_tool_calls is not None and self._tool_calls_run >= self.max_tool_calls

    def _open_call_turn(self, message: str) -> None:
        assert self._record is not None
        self._call_turn = TurnRecord(index=len(self._record.turns), action=message, message=message.strip(),
                                     action_format="openai")
        self._call_turn_texts = []
        self._call_turn_message = {"role": "assistant", "content": message}
        self._record.turns.append(self._call_turn)
        self._record.messages.append(self._call_turn_message)

    def _close_call_turn(self) -> None:
        self._call_turn, self._call_turn_texts, self._call_turn_message = None, [], None

    def _end_episode(self, reason: EndReason, submitted: str | None, info: dict[str, Any]) -> EpisodeEnd:
        """End and score the episode: the one place an episode ends, whichever API ended it."""
        record = self._record
        assert record is not None
        terminated = reason in ANSWER_REASONS
        if reason == TEXT_ANSWER_END_REASON:
            info["end_reason"] = TEXT_ANSWER_END_REASON
            record.metadata["end_reason"] = TEXT_ANSWER_END_REASON
        record.submitted_answer = submitted
        record.terminated, record.truncated = terminated, not terminated
        reward = self._finish_safely(info)
        self._done = True
        self._close_call_turn()
        self._end = EpisodeEnd(
            reason=reason, terminated=terminated, truncated=not terminated, reward=float(reward),
            reward_components=dict(record.reward_components), is_correct=bool(info.get("is_correct", False)),
            safety_violations=safety_violations(record.reward_details), submitted_answer=submitted,
            grader_error=info.get("grader_error"), episode=episode_record(record))
        info["end"] = self._end
        return self._end

    def _budget_spent(self, budget_start: float) -> bool:
        return self.step_time_budget_s is not None and self.clock() - budget_start >= self.step_time_budget_s

    def _is_submit(self, name: Any) -> bool:
        assert self.domain_env is not None
        definition = self.domain_env.toolkit.definitions.get(name) if isinstance(name, str) else None
        return definition is not None and definition.submit

    def _finish_safely(self, info: dict[str, Any]) -> float:
        """`_finish` for `step`, which must never raise: a grader that fails on some hostile answer
        scores the episode 0 with the failure recorded in `reward_details["grader_error"]` and
        `info["grader_error"]`, instead of losing the episode to an exception."""
        try:
            return self._finish(info)
        except Exception as exc:
            record = self._record
            assert record is not None
            error = f"{type(exc).__name__}: {str(exc)[:500]}"
            record.reward, record.reward_components = 0.0, {}
            record.reward_details = {"grader_error": error}
            info.update(reward_components={}, reward_breakdown=record.reward_details, is_correct=False,
                        grader_error=error, trajectory=record)
            return 0.0

    def _finish(self, info: dict[str, Any]) -> float:
        from envs.rewards import score_episode

        record = self._record
        assert record is not None and self.domain_env is not None and self.task is not None
        record.db_hash_final = self.domain_env.db_hash()
        scorer = self.domain_env.scorer or score_episode
        breakdown = scorer(record, self.task, self.reward_weights, self.domain_env.safety_context)
        record.reward = float(breakdown.total)
        record.reward_components = breakdown.components()
        record.reward_details = breakdown.model_dump(mode="json")
        info["reward_components"] = dict(record.reward_components)
        info["reward_breakdown"] = record.reward_details
        info["is_correct"] = bool(breakdown.is_correct)
        info["trajectory"] = record
        return record.reward

    def render(self) -> str | None:
        text = self.transcript()
        if self.render_mode == "human":
            print(text)
            return None
        return text

    # -- records ---------------------------------------------------------------------------------
    def trajectory(self) -> Trajectory:
        """The episode so far as a structured record (a copy)."""
        if self._record is None:
            raise RuntimeError("no episode yet: call reset()")
        return self._record.model_copy(deep=True)

    def transcript(self) -> str:
        if self._record is None:
            return "(no episode: call reset())"
        record = self._record
        content = record.messages[1]["content"]
        if isinstance(content, list):
            content = " ".join(part.get("text") or f"[image: {part.get('image')}]" for part in content)
        lines = [f"=== {record.domain} / {record.task_id} ===", "[user] " + content]
        lines += [self._render_turn(turn) for turn in record.turns]
        if record.reward is not None:
            comps = ", ".join(f"{k}={v:.3f}" for k, v in record.reward_components.items())
            lines.append(f"=== reward {record.reward:.3f} ({comps}) ===")
        return "\n".join(lines)

    @staticmethod
    def _render_turn(turn: TurnRecord) -> str:
        lines = [f"--- turn {turn.index + 1} ({turn.action_format}) ---"]
        if turn.message:
            lines.append(f"[agent] {turn.message}")
        for call in turn.tool_calls:
            args = json.dumps(call.arguments, ensure_ascii=False)
            lines.append(f"[call] {call.name}({args})")
            lines.append(f"[result] {call.result}" if call.ok else f"[error] {call.error}")
        for error in turn.parse_errors:
            lines.append(f"[parse error] {error}")
        if not turn.tool_calls and not turn.parse_errors:
            lines.append(f"[env] {turn.observation}")
        return "\n".join(lines)


def _assistant_message(raw: str, records: list[ToolCallRecord]) -> dict[str, Any]:
    message: dict[str, Any] = {"role": "assistant", "content": raw}
    if records:
        message["tool_calls"] = [
            {"type": "function", "function": {"name": r.name, "arguments": json.dumps(r.arguments, ensure_ascii=False)}}
            for r in records
        ]
    return message


def make_env(domain: str, **kwargs: Any) -> HealthcareGymEnv:
    return HealthcareGymEnv(domain=domain, **kwargs)


