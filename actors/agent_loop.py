"""The multi-turn agent loop, token-in/token-out (TITO).

The prompt is rendered once by the chat template. From then on the loop only appends token ids:

    ids(turn t+1) = ids(turn t) + generated ids + tokenized observation wrapper

where the wrapper is the text the chat template would render between a finished assistant turn
and the next generation prompt (`modeling.model.tool_turn_text` when the turn executed tool calls,
a plain user turn otherwise, matching the environment's own transcript). Nothing is re-rendered,
so the learner trains on exactly the ids the generator sampled, and the loss mask is 1 exactly on
those ids. When a turn is cut by the token limit (no `<|im_end|>` sampled), the loop appends
`<|im_end|>` with mask 0 before the wrapper, so the layout stays what the template renders.

Limits (paper, Appendix D): at most 5 assistant turns, 8,192 prompt tokens, 12,288 response
tokens (everything after the prompt: generated ids and observations). An episode that hits a
limit is flagged `truncated`; `metadata["end_reason"]` says how every episode ended (the env's
`EpisodeEnd.reason`, `envs.episode.EndReason`) and `metadata["truncation"]` names a cut in the
`reward.penalize` vocabulary ("max_turns", "response_tokens"; "" for an answer).

The loop talks to two async callables, so the same code runs in-process (tests, the plain-loop
benchmark, SFT data) and against Ray actors (training):

* an `EnvHandle` (`reset`, `step`, `finish`), e.g. `LocalEnv` below or `actors.env_actor.RemoteEnv`;
* a `generate(request) -> GenerationResult` coroutine, e.g. a `GeneratorService`, a Ray generator
  client, or `GoldReplayPolicy` (the scripted gold-replay policy used for SFT and benchmarks).
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import time
from typing import Any, Awaitable, Callable, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field

from actors.generator import GenerationRequest, GenerationResult
from actors.types import RolloutSample, TurnSpan
from envs.episode import EndReason, EpisodeEnd, cut_observation


class RolloutLimits(BaseModel):
    """Episode limits (paper defaults)."""

    model_config = ConfigDict(extra="forbid")
    max_turns: int = Field(default=5, ge=1, description="assistant turns per episode at most")
    max_prompt_tokens: int = Field(default=8192, ge=1, description="tokens of the initial prompt at most")
    max_response_tokens: int = Field(default=12288, ge=1, description="tokens after the prompt (generated plus tool "
                                                                      "results) per episode at most")
    max_new_tokens_per_turn: int = Field(default=2048, ge=1, description="tokens generated per assistant turn at most")
    # Tiny CPU configs use it to keep sequences short.
    max_observation_chars: int | None = Field(default=None, ge=16, description="tool results longer than this many "
                                                                               "characters are cut (with a marker) "
                                                                               "before tokenization; null = kept whole")


PromptStyle = Literal["env", "compact"]


def compact_system_prompt(tools: list[dict[str, Any]]) -> str:
    """A short system prompt for tiny CPU models: the call format and the tool names.

    The environment's own system prompt (policy text plus full JSON schemas, 15-22K characters)
    is what large models should see; a 1M-parameter model on 2 CPU cores cannot afford a
    4K-token prompt on every turn, so the tiny configs use this instead (`rollout.system_prompt`)
    and learn the arguments from the gold-replay warm start.
    """
    from envs.env import CALL_FORMAT_HELP

    names = [schema.get("function", schema)["name"] for schema in tools]
    return f"{CALL_FORMAT_HELP}\nTools: " + ", ".join(names)


class EpisodeSpec(BaseModel):
    """Everything needed to (re-)run one episode from its start."""

    model_config = ConfigDict(extra="forbid")
    sample_id: str
    task_id: str
    domain: str
    split: str | None = None
    group_id: str
    group_index: int = 0
    seed: int
    min_version: int = 0  # the generator must hold at least this policy version
    greedy: bool = False  # argmax decoding (validation)


class PromptTooLongError(ValueError):
    """The rendered prompt exceeds `max_prompt_tokens`; the task cannot be rolled out."""


class EnvHandle(Protocol):
    """An episode's env, in-process or remote. `step` is the env's `step(text)`; a step that ends the
    episode carries its `EpisodeEnd` in `info["end"]`; `finish(reason)` cuts the episode (an
    `EndReason`) and returns its `EpisodeEnd` (idempotent)."""

    async def reset(self, spec: EpisodeSpec) -> tuple[str, dict[str, Any]]: ...
    async def step(self, action: str) -> tuple[str, float, bool, bool, dict[str, Any]]: ...
    async def finish(self, reason: EndReason) -> EpisodeEnd: ...
    async def close(self) -> None: ...


GenerateFn = Callable[[GenerationRequest], Awaitable[GenerationResult]]


def turn_seed(episode_seed: int, turn: int) -> int:
    """A sampling seed per (episode, turn): re-running an episode re-samples the same tokens."""
    digest = hashlib.blake2b(f"{episode_seed}:{turn}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") & 0x7FFF_FFFF_FFFF_FFFF


def finish_episode(env, reason: EndReason | str = "token_limit") -> EpisodeEnd:
    """Score an episode the agent loop had to stop (a token limit) before the env ended it.

    The env scores it (`HealthcareGymEnv.finish`: the domain's own scorer, as a turn-limit
    truncation); nothing here re-implements scoring. Idempotent, as `finish` is.
    """
    return env.unwrapped.finish(reason=reason)


#: How training's `metadata["truncation"]` (what `reward.penalize` names) calls a cut end.
TRUNCATION_LABELS: dict[str, str] = {"turn_limit": "max_turns", "token_limit": "response_tokens"}


def truncation_label(end: EpisodeEnd) -> str:
    """`metadata["truncation"]` of an episode: "" when the agent answered, else the cut's name in the
    `reward.penalize` vocabulary ("max_turns", "response_tokens") or its end reason."""
    return "" if end.terminated else TRUNCATION_LABELS.get(end.reason, end.reason)


def make_env(domain: str, split: str | None, max_turns: int, env_kwargs: dict[str, Any] | None = None):
    """A `HealthcareGymEnv` (the class registered as HealthcareGym-v0), built directly.

    Direct construction rather than `gymnasium.make`: it does not depend on `envs/__init__.py`
    having run its registration in this process (a stale editable install can import `envs` as a
    namespace package, which skips it).
    """
    from envs.env import HealthcareGymEnv

    return HealthcareGymEnv(domain=domain, split=split, max_turns=max_turns, **(env_kwargs or {}))


class LocalEnv:
    """An in-process `EnvHandle` around a `HealthcareGymEnv` (one episode at a time)."""

    def __init__(self, max_turns: int, env_kwargs: dict[str, Any] | None = None) -> None:
        self.max_turns = max_turns
        self.env_kwargs = dict(env_kwargs or {})
        self._envs: dict[tuple[str, str | None], Any] = {}
        self.env = None

    async def reset(self, spec: EpisodeSpec) -> tuple[str, dict[str, Any]]:
        key = (spec.domain, spec.split)
        if key not in self._envs:
            self._envs[key] = make_env(spec.domain, spec.split, self.max_turns, self.env_kwargs)
        self.env = self._envs[key]
        obs, info = self.env.reset(seed=spec.seed, options={"task_id": spec.task_id})
        return obs, info

    async def step(self, action: str) -> tuple[str, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:  # what crosses a process boundary: the typed end, no pydantic record
            info = {k: v for k, v in info.items() if k not in ("trajectory", "reward_breakdown")}
        return obs, float(reward), terminated, truncated, info

    async def finish(self, reason: EndReason) -> EpisodeEnd:
        return finish_episode(self.env, reason)

    async def close(self) -> None:
        return None


class AgentLoop:
    """Runs one episode TITO and returns a `RolloutSample`.

    Args:
        tokenizer: The policy's tokenizer (ChatML template, `<|im_end|>` as EOS).
        limits: Turn and token limits.
        prompt_style: "env" renders the environment's system prompt (policy and tool schemas);
            "compact" renders `compact_system_prompt` (tiny CPU models).
    """

    def __init__(self, tokenizer, limits: RolloutLimits, prompt_style: PromptStyle = "env") -> None:
        from modeling.model import IM_END, IM_START

        if prompt_style not in ("env", "compact"):
            raise ValueError(f"prompt_style must be 'env' or 'compact', got {prompt_style!r}")
        self.tokenizer = tokenizer
        self.limits = limits
        self.prompt_style = prompt_style
        self.im_end_id = tokenizer.convert_tokens_to_ids(IM_END)
        self.im_start = IM_START
        self.im_end = IM_END
        if self.im_end_id is None or self.im_end_id == tokenizer.unk_token_id:
            raise ValueError(f"tokenizer has no {IM_END} token; the agent loop needs a ChatML tokenizer")

    # -- rendering -----------------------------------------------------------------------------
    def render_prompt(self, info: dict[str, Any]) -> list[int]:
        """Render the first prompt once with the chat template (system policy + tools, then the ticket)."""
        system = info["system_prompt"] if self.prompt_style == "env" else compact_system_prompt(info["tools"])
        messages = [{"role": "system", "content": system}, {"role": "user", "content": info["ticket"]}]
        text = self.tokenizer.apply_chat_template(messages, tokenize=False, add_generation_prompt=True)
        return list(self.tokenizer.encode(text, add_special_tokens=False))

    def observation_text(self, observation: str, had_tool_calls: bool) -> str:
        """What the template renders after a finished assistant turn, up to the next generation prompt."""
        from modeling.model import tool_turn_text

        observation = cut_observation(observation, self.limits.max_observation_chars)
        if had_tool_calls:
            return tool_turn_text(observation)
        return f"\n{self.im_start}user\n{observation}{self.im_end}\n{self.im_start}assistant\n"

    def observation_ids(self, observation: str, had_tool_calls: bool) -> list[int]:
        return list(self.tokenizer.encode(self.observation_text(observation, had_tool_calls),
                                          add_special_tokens=False))

    def action_text(self, token_ids: list[int]) -> str:
        """The assistant's raw text for the environment: the generated ids without the stop token."""
        ids = token_ids[:-1] if token_ids and token_ids[-1] == self.im_end_id else token_ids
        return self.tokenizer.decode(ids, skip_special_tokens=True)

    # -- the loop --------------------------------------------------------------------------------
    async def run(self, spec: EpisodeSpec, env: EnvHandle, generate: GenerateFn) -> RolloutSample:
        """Run the episode from its start (reset with `spec.seed`) to the end or a limit."""
        limits = self.limits
        timings = {"generate_s": 0.0, "env_s": 0.0}
        t0 = time.perf_counter()
        obs, info = await env.reset(spec)
        timings["env_s"] += time.perf_counter() - t0
        ids = self.render_prompt(info)
        prompt_length = len(ids)
        if prompt_length > limits.max_prompt_tokens:
            raise PromptTooLongError(
                f"task {spec.task_id!r} ({spec.domain}): prompt of {prompt_length} tokens exceeds "
                f"rollout.max_prompt_tokens={limits.max_prompt_tokens}"
            )
        mask = [0] * prompt_length
        logprobs = [0.0] * prompt_length
        versions = [-1] * prompt_length
        turns: list[TurnSpan] = []
        num_tool_calls = 0
        end: EpisodeEnd | None = None
        limit_hit: EndReason | None = None  # a limit of this loop that cut the episode
        turn = 0
        while True:
            budget = limits.max_response_tokens - (len(ids) - prompt_length)
            if budget <= 0:
                limit_hit = "token_limit"
                break
            request = GenerationRequest(
                request_id=f"{spec.sample_id}:t{turn}", prompt_ids=ids,
                max_new_tokens=min(limits.max_new_tokens_per_turn, budget),
                seed=turn_seed(spec.seed, turn), min_version=spec.min_version, greedy=spec.greedy,
            )
            t0 = time.perf_counter()
            result = await generate(request)
            timings["generate_s"] += time.perf_counter() - t0
            if not result.token_ids:
                raise RuntimeError(f"generator returned no tokens for {request.request_id}")
            if len(result.logprobs) != len(result.token_ids):
                raise RuntimeError(f"generator returned {len(result.logprobs)} log-probs for "
                                   f"{len(result.token_ids)} tokens ({request.request_id})")
            start = len(ids)
            ids.extend(result.token_ids)
            mask.extend([1] * len(result.token_ids))
            logprobs.extend(result.logprobs)
            versions.extend([result.policy_version] * len(result.token_ids))
            cut = result.token_ids[-1] != self.im_end_id
            turns.append(TurnSpan(start=start, end=len(ids), truncated=cut))
            turn += 1

            t0 = time.perf_counter()
            observation, reward, terminated, env_truncated, step_info = await env.step(self.action_text(result.token_ids))
            timings["env_s"] += time.perf_counter() - t0
            num_tool_calls += len(step_info.get("tool_calls") or [])
            if terminated or env_truncated:  # an env actor ends an episode whose env raised as "env_error"
                end = step_info["end"]
                break
            tail = ([self.im_end_id] if cut else []) + self.observation_ids(
                observation, bool(step_info.get("tool_calls")))
            room = limits.max_response_tokens - (len(ids) - prompt_length)
            if len(tail) >= room:
                # The observation does not fit: keep what fits, and the episode ends here.
                tail = tail[:max(room, 0)]
                limit_hit = "token_limit"
            ids.extend(tail)
            mask.extend([0] * len(tail))
            logprobs.extend([0.0] * len(tail))
            versions.extend([-1] * len(tail))
            if limit_hit:
                break
            if turn >= limits.max_turns:  # the env enforces it too; this guards a mis-configured env
                limit_hit = "turn_limit"
                break

        if end is None:
            t0 = time.perf_counter()
            end = await env.finish(limit_hit or "token_limit")
            timings["env_s"] += time.perf_counter() - t0
        await env.close()
        response_tokens = sum(mask)
        return RolloutSample(
            sample_id=spec.sample_id, task_id=spec.task_id, domain=spec.domain, group_id=spec.group_id,
            seed=spec.seed, prompt_length=prompt_length, input_ids=ids, loss_mask=mask,
            sampling_logprobs=logprobs, policy_versions=versions, turns=turns,
            env_reward=end.reward, env_correct=end.is_correct,
            reward=end.reward, reward_components=dict(end.reward_components),
            correct=end.is_correct, truncated=end.truncated, num_tool_calls=num_tool_calls,
            response_tokens=response_tokens, episode=end.episode,
            metadata={"truncation": truncation_label(end), "end_reason": end.reason, "num_turns": len(turns),
                      "group_index": spec.group_index, "split": spec.split, **timings,
                      **({"env_error": end.env_error} if end.env_error else {})},
        )


# ---------------------------------------------------------------------------------------------
# The scripted gold-replay policy (SFT data, rollout benchmark)
# ---------------------------------------------------------------------------------------------


def gold_turn_actions(task, max_turns: int) -> list[str]:
    """The gold solution as at most `max_turns` assistant actions: the expected tool calls (packed
    several per turn when there are more than `max_turns - 1`), then `submit_answer`."""
    from envs.validate import gold_actions_as_text, gold_answer_text

    calls = gold_actions_as_text(task)
    submit = "<tool_call>" + json.dumps(
        {"name": "submit_answer", "arguments": {"answer": gold_answer_text(task) or ""}}, ensure_ascii=False
    ) + "</tool_call>"
    slots = max_turns - 1
    if slots <= 0:
        return [submit]
    if len(calls) <= slots:
        return calls + [submit]
    per_turn = -(-len(calls) // slots)  # ceil
    packed = ["\n".join(calls[i:i + per_turn]) for i in range(0, len(calls), per_turn)]
    return packed + [submit]


class GoldReplayPolicy:
    """A `generate` coroutine that "samples" the gold action of each turn (log-prob 0).

    It is a policy, not a model: the environment executes its actions for real, so tool results,
    rewards and the token layout are the ones training sees.

    Args:
        tokenizer: The policy tokenizer.
        actions: task id -> the gold actions of each turn (`gold_turn_actions`).
    """

    def __init__(self, tokenizer, actions: dict[str, list[str]]) -> None:
        from modeling.model import IM_END

        self.tokenizer = tokenizer
        self.actions = actions
        self.im_end_id = tokenizer.convert_tokens_to_ids(IM_END)
        self._turns: dict[str, int] = {}

    async def __call__(self, request: GenerationRequest) -> GenerationResult:
        sample_id, _, turn = request.request_id.rpartition(":t")
        task_actions = self.actions[self._task_of(sample_id)]
        turn_index = int(turn)
        text = task_actions[min(turn_index, len(task_actions) - 1)]
        ids = list(self.tokenizer.encode(text, add_special_tokens=False)) + [self.im_end_id]
        finish = "stop"
        if len(ids) > request.max_new_tokens:
            ids, finish = ids[:request.max_new_tokens], "length"
        await asyncio.sleep(0)
        return GenerationResult(request_id=request.request_id, token_ids=ids, logprobs=[0.0] * len(ids),
                                finish_reason=finish, policy_version=0)

    @staticmethod
    def _task_of(sample_id: str) -> str:
        # sample ids are f"{task_id}:{group_index}:{seed}" (actors.types)
        return sample_id.rsplit(":", 2)[0]
