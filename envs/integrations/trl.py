"""TRL: an environment factory for `GRPOTrainer(environment_factory=...)` and per-dimension rewards.

TRL's contract (trl 1.16 `GRPOTrainer`): it builds one instance per concurrent rollout, pools the
instances and reuses them through `reset(**row)` (every dataset column as a keyword); every public
method of the class other than `reset` / `get_reward` is a tool, its schema read from the type hints
and Google-style docstring (`transformers.utils.get_json_schema`); TRL calls `method(**arguments)`
and shows the returned text as the tool's result; reward functions receive `environments=`, the
instances of the batch's rollouts, in order.

`environment_class(domain)` generates such a class from the domain's tool schemas: one method per
tool with a keyword-only typed signature and a docstring from which TRL rebuilds the same schema
(a schema `default` aside: `get_json_schema` does not emit defaults), each call going through
`HealthcareGymEnv.call_tool`. A rollout ends where TRL stops it; the reward functions
(`reward_functions()`) first end the episode through `HealthcareGymEnv.finish` (the last reply's
text graded as the answer; a rollout cut while still calling tools scored as a turn-limit cut) and
then read one dimension of the env's own `reward_components`. The class owns no `get_reward`, so
the trainer's rewards are exactly these functions (weights: `reward_weights()`).

```python
from datasets import load_dataset
from trl import GRPOConfig, GRPOTrainer
from envs.integrations.trl import environment_class, reward_functions, reward_weights

dataset = load_dataset("parquet", data_files="tasks/psychiatry.parquet", split="train")  # hcgym tasks export
trainer = GRPOTrainer(model=..., train_dataset=dataset, environment_factory=environment_class("psychiatry"),
                      reward_funcs=reward_functions(), args=GRPOConfig(..., reward_weights=reward_weights()))
```
"""

from __future__ import annotations

import inspect
import keyword
import threading
from collections import deque
from typing import Any, Literal

from envs.episode import EpisodeEnd
from envs.rewards.dimensions import ALWAYS_REPORTED

#: The reward dimensions every episode reports, then the weighted total: one TRL reward function each.
DIMENSIONS: tuple[str, ...] = ALWAYS_REPORTED
REWARD_NAMES: tuple[str, ...] = DIMENSIONS + ("total",)

#: Member names TRL treats specially (`reset` starts a rollout, `get_reward` becomes a reward
#: column) and the attributes the generated class keeps for itself; a tool of that name could not
#: be a TRL tool. Names starting with "_" are never tools for TRL either.
RESERVED_NAMES: frozenset[str] = frozenset({"reset", "get_reward", "env", "domain", "env_kwargs", "episodes"})

#: How many finished rollouts a generated class keeps in `episodes`.
EPISODE_LOG_SIZE = 1024

_JSON_TYPES: dict[str, Any] = {"string": str, "integer": int, "number": float, "boolean": bool,
                               "object": dict, "array": list}


def reserved_name_problems(tool_names: list[str]) -> list[str]:
    """Why each name could not be a method of a TRL environment class (empty when all can)."""
    problems = []
    for name in tool_names:
        if name in RESERVED_NAMES:
            problems.append(f"tool {name!r} is a reserved name for TRL's environment_factory "
                            f"({', '.join(sorted(RESERVED_NAMES))})")
        elif name.startswith("_"):
            problems.append(f"tool {name!r} starts with '_': TRL never exposes such a method as a tool")
        elif not name.isidentifier() or keyword.iskeyword(name):
            problems.append(f"tool {name!r} is not a Python identifier, so it cannot be a method")
    return problems


def _annotation(name: str, prop: dict[str, Any]) -> Any:
    """The Python type from which `transformers.utils.get_json_schema` writes `prop` back."""
    kind = prop.get("type")
    if "enum" in prop:
        return Literal[tuple(prop["enum"])]
    if kind == "array":
        items = prop.get("items")
        return list[_annotation(name, items)] if items else list
    if kind not in _JSON_TYPES:
        raise ValueError(f"parameter {name!r}: JSON schema type {kind!r} has no Python type for TRL")
    return _JSON_TYPES[kind]


def _one_line(text: str) -> str:
    # An argument description spanning lines could read as a new "name:" entry to the docstring parser.
    return " ".join(text.split())


def _tool_method(schema: dict[str, Any]):
    function = schema["function"]
    name = function["name"]
    parameters = function.get("parameters") or {}
    properties: dict[str, Any] = parameters.get("properties") or {}
    required = set(parameters.get("required") or [])
    params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    annotations: dict[str, Any] = {}
    for arg, prop in properties.items():
        if not arg.isidentifier() or keyword.iskeyword(arg):
            raise ValueError(f"tool {name!r}: parameter {arg!r} is not a Python identifier")
        annotations[arg] = _annotation(f"{name}.{arg}", prop)
        # Keyword-only: a required argument may follow an optional one, as in the schema's order.
        default = inspect.Parameter.empty if arg in required else prop.get("default")
        params.append(inspect.Parameter(arg, inspect.Parameter.KEYWORD_ONLY, default=default,
                                        annotation=annotations[arg]))

    def tool(self, **arguments: Any) -> str:
        return self._call(name, arguments)

    tool.__name__ = tool.__qualname__ = name
    tool.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    tool.__annotations__ = annotations
    doc = function.get("description") or name
    if properties:
        doc += "\n\nArgs:\n" + "\n".join(f"    {arg}: {_one_line(prop.get('description') or arg)}"
                                          for arg, prop in properties.items())
    tool.__doc__ = doc
    return tool


class HealthcareGymTRLEnv:
    """The base of the generated classes: one `HealthcareGymEnv` per instance, reset per rollout.

    Attributes:
        domain: The domain (a class attribute of each generated class).
        env: This instance's `HealthcareGymEnv`.
        episodes: Class-wide record of the last `EPISODE_LOG_SIZE` finished rollouts'
            `(task_id, EpisodeEnd)`, in the order they ended (to compare the trainer's logged
            rewards with, or to inspect episodes); bounded, as a training run ends many thousands.
    """

    domain: str = ""
    env_kwargs: dict[str, Any] = {}
    episodes: deque[tuple[str, EpisodeEnd]] = deque(maxlen=EPISODE_LOG_SIZE)

    def __init__(self) -> None:
        from envs.env import HealthcareGymEnv

        self.env = HealthcareGymEnv(domain=self.domain, **self.env_kwargs)
        self._lock = threading.Lock()
        self._task_id: str | None = None
        self._recorded = False

    def reset(self, **row: Any) -> None:
        """Start the row's task (`task_id` column of `hcgym tasks export`); the prompt is the row's."""
        task_id = row.get("task_id")
        if not isinstance(task_id, str):
            raise ValueError(f"{type(self).__name__}.reset: the dataset row has no 'task_id' column "
                             f"(columns: {', '.join(sorted(row))}); export rows with `hcgym tasks export`")
        if row.get("domain") not in (None, self.domain):
            raise ValueError(f"{type(self).__name__}.reset: row of task {task_id!r} is domain "
                             f"{row['domain']!r}, this environment serves {self.domain!r}")
        self.env.reset(options={"task_id": task_id})
        self._task_id = task_id
        self._recorded = False
        return None

    def _call(self, name: str, arguments: dict[str, Any]) -> str:
        # Each TRL tool call is one assistant turn: TRL runs a reply's calls one by one and does not
        # tell the environment where a reply starts.
        with self._lock:
            return self.env.call_tool(name, arguments, message="").observation

    def _finish(self, completion: Any) -> EpisodeEnd:
        """End the rollout's episode (idempotent): its last reply's text is the answer, unless that
        reply still called tools (TRL stopped it at its tool-call or length limit: a cut)."""
        with self._lock:
            end = self.env.end
            if end is None:
                last = _last_assistant(completion)
                if last is None or last.get("tool_calls"):
                    end = self.env.finish(reason="turn_limit")
                else:
                    end = self.env.finish(final_text=_text(last.get("content")))
            if not self._recorded:
                self._recorded = True
                type(self).episodes.append((self._task_id or "", end))
            return end


def _text(content: Any) -> str:
    if isinstance(content, list):
        return "".join(part.get("text", "") for part in content if isinstance(part, dict))
    return content or ""


def _last_assistant(completion: Any) -> dict[str, Any] | None:
    if isinstance(completion, str):
        return {"role": "assistant", "content": completion}
    for message in reversed(completion or []):
        if message.get("role") == "assistant":
            return message
    return None


def environment_class(domain: str, **env_kwargs: Any) -> type[HealthcareGymTRLEnv]:
    """A TRL environment class for one domain: tool methods generated from the domain's schemas.

    Args:
        domain: A registered domain.
        **env_kwargs: `HealthcareGymEnv` arguments (`max_turns` counts tool calls here, one turn
            each; default 64; `max_tool_calls`, `max_tool_result_chars`, `reward_weights`, ...).

    Raises:
        ValueError: A tool whose name TRL reserves (`reserved_name_problems`) or whose parameters
            have no Python form.
    """
    from envs.env import HealthcareGymEnv

    kwargs = {"max_turns": 64, **env_kwargs}
    if "split" in kwargs or "task_id" in kwargs:
        raise ValueError("environment_class: the dataset row picks the task (its task_id); pass no split/task_id")
    env = HealthcareGymEnv(domain=domain, **kwargs)
    schemas = list(env.tool_schemas)
    if env._schema_env().on_reset is not None:
        # A toolkit composed at reset (cross_domain's phases) differs per task, while TRL reads a
        # class's tools once: the class offers every task's tools (a call to a tool the running
        # task lacks is answered as an unknown tool by the env).
        seen = {s["function"]["name"] for s in schemas}
        for task in env.tasks:
            env.reset(options={"task_id": task.id})
            for schema in env.tool_schemas:
                if schema["function"]["name"] not in seen:
                    seen.add(schema["function"]["name"])
                    schemas.append(schema)
    problems = reserved_name_problems([s["function"]["name"] for s in schemas])
    if problems:
        raise ValueError(f"domain {domain!r}: " + "; ".join(problems))
    members: dict[str, Any] = {"domain": domain, "env_kwargs": kwargs, "episodes": deque(maxlen=EPISODE_LOG_SIZE),
                               "__doc__": f"HealthcareGym {domain!r} for TRL's GRPOTrainer(environment_factory=...)."}
    for schema in schemas:
        members[schema["function"]["name"]] = _tool_method(schema)
    class_name = "".join(part.capitalize() for part in domain.split("_")) + "Env"
    return type(class_name, (HealthcareGymTRLEnv,), members)


def _reward_function(dimension: str):
    def reward(completions: list[Any], environments: list[HealthcareGymTRLEnv] | None = None,
               **_: Any) -> list[float]:
        if environments is None:
            raise ValueError(f"reward_{dimension}: TRL passed no environments; use it with "
                             "GRPOTrainer(environment_factory=environment_class(domain))")
        return [float(env._finish(completion).reward_components.get(dimension, 0.0))
                for env, completion in zip(environments, completions, strict=True)]

    reward.__name__ = reward.__qualname__ = f"reward_{dimension}"
    reward.__doc__ = f"The env's {dimension!r} reward component of each rollout (ends its episode first)."
    return reward


def reward_functions() -> list[Any]:
    """TRL reward functions, one per `REWARD_NAMES` entry (logged as `rewards/reward_<name>/mean`)."""
    return [_reward_function(name) for name in REWARD_NAMES]


def reward_weights(train_on: str = "total") -> list[float]:
    """`GRPOConfig.reward_weights` for `reward_functions()`: weight 1 on `train_on`, 0 elsewhere
    (the others are logged, not trained on)."""
    if train_on not in REWARD_NAMES:
        raise ValueError(f"train_on={train_on!r}: one of {', '.join(REWARD_NAMES)}")
    return [1.0 if name == train_on else 0.0 for name in REWARD_NAMES]
