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
TEXT_ANSWER_END_REASON = "text_answer"
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


class HealthcareGymEnv(gym.Env[str, str]):
    """A Gymnasium environment over one clinical domain.

    Args:
        domain: Registered domain name (see `envs.registry.list_domains()`).
        task_id: Fix the task; otherwise each reset samples one from the split with the env's RNG.
        split: Task split ("train", "test", ...); None for all tasks of the domain.
        max_turns: Agent turns before the episode is truncated.
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

    Attributes:
        clock: The monotonic clock the step budget reads (`time.perf_counter`); tests inject one.
    """

    metadata = {"render_modes": ["ansi", "human"]}

    def __init__(self, domain: str = "drug_interaction", task_id: str | None = None, split: str | None = None,
                 max_turns: int = 10, render_mode: str | None = None,
                 reward_weights: dict[str, float] | None = None,
                 step_time_budget_s: float | None = STEP_TIME_BUDGET_S,
                 text_turn_ends_episode: bool = False) -> None:
        from envs import registry

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        if not isinstance(max_turns, int) or max_turns < 1:
            raise ValueError(f"max_turns must be a positive integer, got {max_turns!r}")
        if step_time_budget_s is not None and (
                isinstance(step_time_budget_s, bool) or not isinstance(step_time_budget_s, (int, float))
                or not math.isfinite(step_time_budget_s) or step_time_budget_s < 0):
            raise ValueError(f"step_time_budget_s must be a finite number of seconds >= 0 or None, "
                             f"got {step_time_budget_s!r}")
        if not isinstance(text_turn_ends_episode, bool):
            raise ValueError(f"text_turn_ends_episode must be true or false, got {text_turn_ends_episode!r}")
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
        for call in parsed.calls:
            if self._budget_spent(budget_start) and not self._is_submit(call.name):
                over_budget.append(call.name if isinstance(call.name, str) else safe_repr(call.name, 80))
                continue
            call_start = time.perf_counter()
            outcome: ToolOutcome = toolkit.call(call.name, call.arguments)
            text = outcome.as_text()
            if len(text) > MAX_TOOL_RESULT_CHARS:
                text = text[:MAX_TOOL_RESULT_CHARS] + f"\n[truncated: result longer than {MAX_TOOL_RESULT_CHARS} characters]"
            records.append(ToolCallRecord(
                name=outcome.name, arguments=outcome.arguments, result=text if outcome.ok else None,
                error=outcome.error, error_kind=outcome.error_kind,
                tool_type=str(outcome.tool_type) if outcome.tool_type else None,
                format=call.format, submit=outcome.submit, duration_s=time.perf_counter() - call_start,
            ))
            parts.append(text if len(parsed.calls) == 1 else f"[{outcome.name}] {text}")
            if outcome.submit and outcome.ok:
                submitted = str(outcome.arguments.get("answer", ""))
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

        terminated = submitted is not None
        truncated = not terminated and len(self._record.turns) >= self.max_turns
        reward = 0.0
        info: dict[str, Any] = {"turn": turn_index, "tool_calls": [r.name for r in records],
                                "action_format": parsed.format, "parse_errors": parsed.errors,
                                # kinds of the calls that failed (unknown_tool, invalid_arguments, ...)
                                "tool_errors": [r.error_kind for r in records if r.error_kind]}
        if over_budget:
            info["calls_over_budget"] = len(over_budget)
        if ended_by_text:
            info["end_reason"] = TEXT_ANSWER_END_REASON
            self._record.metadata["end_reason"] = TEXT_ANSWER_END_REASON
        if terminated or truncated:
            self._record.submitted_answer = submitted
            self._record.terminated, self._record.truncated = terminated, truncated
            reward = self._finish_safely(info)
            self._done = True
        if self.render_mode == "human":
            print(self._render_turn(turn))
        return observation, reward, terminated, truncated, info

    def _budget_spent(self, budget_start: float) -> bool:
        return self.step_time_budget_s is not None and self.clock() - budget_start >= self.step_time_budget_s

    def _is_submit(self, name: Any) -> bool:
        assert self.domain_env is not None
        definition = self.domain_env.toolkit.definitions.get(name) if isinstance(name, str) else None
        return definition is not None and definition.submit

    def truncate(self, reason: str) -> tuple[float, dict[str, Any]]:
        """End the running episode from outside the env (an agent runner's token or context limit),
        scored exactly as a turn-limit truncation: by the domain's own scorer.

        Args:
            reason: Why the runner stopped (e.g. "token_limit"); returned as `info["end_reason"]`.

        Returns:
            (reward, info) with the same reward keys as the terminal `step`'s info.
        """
        if self._record is None:
            raise RuntimeError("call reset() before truncate()")
        if self._done:
            raise RuntimeError(f"episode of task {self._record.task_id!r} is already over")
        self._record.terminated, self._record.truncated = False, True
        info: dict[str, Any] = {"end_reason": reason}
        reward = self._finish_safely(info)  # a grader failure is recorded, as at a terminal step
        self._done = True
        return reward, info

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


