"""SkyRL: the gym as a skyrl-gym `BaseTextEnv`, the environment SkyRL's generator drives.

skyrl-gym 0.4's contract: the generator builds one env per trajectory with
`skyrl_gym.make(env_class, env_config=..., extras=...)`, where `extras` is the dataset row without
its prompt and `env_class` columns (plus `max_turns` from the generator config); `init(prompt)`
returns the chat the model starts from; every model reply, as text, goes to `step(action)`, which
returns the next observation messages, the reward, `done` and metadata; `get_metrics()` is logged
per trajectory and averaged by `aggregate_metrics`.

The rows are `hcgym tasks export`'s (their `task_id` and `domain` columns pick the episode). SkyRL
renders the chat with the tokenizer's template and no tool list, so `init` starts from the env's
text-agent prompt (policy, call format and tool block in the system message, then the ticket), and
each reply runs through `HealthcareGymEnv.step`, which parses the tool calls in the text: the same
episode core, limits and scoring as every other way in (envs/README.md, "public API"); a reply
without a tool call ends the episode as a text answer. The reward
is the episode's 5D total, given on the step that ends it (0 before); its components are in that
step's metadata and in `get_metrics()`.

```python
import skyrl_gym
from envs.integrations.skyrl import ENV_ID, register

register()                    # in SkyRL's entrypoint task, before the trainer builds envs
env = skyrl_gym.make(ENV_ID, env_config={"max_tool_calls": 20}, extras=row)   # row: an exported task
chat, _ = env.init(row["prompt"])
out = env.step(model_reply)   # observations, reward, done, metadata
```
"""

from __future__ import annotations

from typing import Any

from skyrl_gym.envs.base_text_env import BaseTextEnv, BaseTextEnvStepOutput

from envs.env import HealthcareGymEnv

#: The `env_class` the environment is registered under (a dataset row's `env_class` column, or the
#: generator's default env class).
ENV_ID = "healthcare_gym"
#: Assistant turns when neither the row nor the generator sets `max_turns`.
DEFAULT_MAX_TURNS = 10
#: `env_config` keys passed on to `HealthcareGymEnv` (the rest of the constructor is the row's).
ENV_CONFIG_KEYS = frozenset({"max_tool_calls", "max_tool_result_chars", "reward_weights", "step_time_budget_s",
                             "text_turn_ends_episode"})


def register(env_id: str = ENV_ID) -> None:
    """Register the environment with skyrl-gym under `env_id` (again: nothing changes)."""
    from skyrl_gym.envs.registration import register as skyrl_register, registry

    if env_id not in registry:
        skyrl_register(id=env_id, entry_point=f"{__name__}:HealthcareSkyRLEnv")


class HealthcareSkyRLEnv(BaseTextEnv):
    """One episode of the task a dataset row names.

    Args:
        env_config: Keyword arguments for `HealthcareGymEnv` (`ENV_CONFIG_KEYS`), from SkyRL's
            `environment.skyrl_gym.<env_class>` config.
        extras: The dataset row (an exported task: `task_id`, `domain`, ...) and `max_turns`.

    Raises:
        ValueError: naming the missing row column or the unknown `env_config` key.
    """

    def __init__(self, env_config: Any = None, extras: dict[str, Any] | None = None) -> None:
        super().__init__()
        extras = dict(extras or {})
        missing = [key for key in ("task_id", "domain") if not extras.get(key)]
        if missing:
            raise ValueError(f"extras: missing {', '.join(missing)} (the row needs the columns of `hcgym tasks "
                             f"export`); got keys {sorted(extras)}")
        # A reply without a tool call is the answer (graded as `submit_answer` with its text), as
        # SkyRL's generator ends a trajectory only when the env says done.
        config = {"text_turn_ends_episode": True, **dict(env_config or {})}
        unknown = sorted(set(config) - ENV_CONFIG_KEYS)
        if unknown:
            raise ValueError(f"env_config: unknown keys {unknown}; expected some of {sorted(ENV_CONFIG_KEYS)}")
        self.max_turns = int(extras.get("max_turns") or DEFAULT_MAX_TURNS)
        self.task_id = str(extras["task_id"])
        self.env = HealthcareGymEnv(domain=str(extras["domain"]), max_turns=self.max_turns, **config)

    def init(self, prompt: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """Start the row's task; the chat is the env's text-agent prompt (the row's `prompt` has the
        same ticket but no tool block, which SkyRL's template would not add)."""
        self.env.reset(options={"task_id": self.task_id})
        parts = self.env.prompt()
        chat = [{"role": "system", "content": parts.system_prompt}, *parts.messages()[1:]]
        return chat, {"task_id": self.task_id, "domain": self.env.domain_name}

    def step(self, action: str) -> BaseTextEnvStepOutput:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.turns += 1
        if terminated or truncated:
            end = self.env.end
            return BaseTextEnvStepOutput(observations=[], reward=float(reward), done=True,
                                         metadata={"reason": end.reason, "is_correct": end.is_correct,
                                                   "reward_components": dict(self.env.reward_components)})
        # Tool results come back as the tool's turn, other feedback (a parse error) as the user's.
        role = "tool" if info.get("tool_calls") else "user"
        return BaseTextEnvStepOutput(observations=[{"role": role, "content": observation}], reward=0.0,
                                     done=False, metadata={"tool_calls": info.get("tool_calls", [])})

    def get_metrics(self) -> dict[str, Any]:
        """The ended episode's reward components and turns (SkyRL averages them over trajectories)."""
        metrics: dict[str, Any] = {"turns": self.turns}
        if self.env.done:
            metrics.update({f"reward_{name}": value for name, value in self.env.reward_components.items()})
        return metrics

    def close(self) -> None:
        self.env.close()
