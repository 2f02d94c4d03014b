"""`HealthcareGymClient`: OpenEnv's WebSocket client (`EnvClient`) with this environment's types.

One client is one server session (one environment, isolated from every other session). `reset`
takes the task (`task_id`, or `split` and `index`, or `split` and `seed`; `domain`); `call_tool`
runs a task tool (`arguments` a dict; `message` the assistant text of the turn the call opens); `finish` ends
the episode with a text answer or a cut. The call that ends an episode has `done`, `reward` and the
score in `observation.metadata` (`reward_components`, `score`).

```python
from envs.integrations.openenv.client import HealthcareGymClient

with HealthcareGymClient(base_url="http://127.0.0.1:8000").sync() as env:
    first = env.reset(domain="drug_interaction", split="test", seed=0)
    print(first.observation.prompt["ticket"])
    step = env.call_tool("lookup_drug", {"name": "warfarin"}, message="Let me check the drug.")
    print(step.observation.result)
    end = env.finish(final_text="The interaction is major.")
    print(end.reward, end.observation.metadata["reward_components"])
```

Without this package, OpenEnv's `GenericEnvClient` speaks the same protocol with dicts, and its
`MCPToolClient` reaches the same tools over `/mcp` (`list_tools`, `call_tool`).
"""

from __future__ import annotations

from typing import Any

from openenv.core.client_types import StepResult
from openenv.core.env_client import EnvClient

from envs.integrations.openenv.models import (MESSAGE_META_KEY, SAME_TURN_META_KEY, CallToolAction, CallToolObservation,
                                              HealthcareGymObservation, HealthcareGymState, ListToolsAction,
                                              ListToolsObservation)


class HealthcareGymClient(EnvClient[Any, Any, HealthcareGymState]):
    """A session on a HealthcareGym OpenEnv server (`hcgym serve --openenv`); pass
    `headers={"Authorization": f"Bearer {token}"}` to a server that has a token."""

    def _step_payload(self, action: Any) -> dict[str, Any]:
        if not isinstance(action, (CallToolAction, ListToolsAction)):
            raise TypeError(f"a HealthcareGym action is a CallToolAction or ListToolsAction, got {type(action).__name__}")
        return action.model_dump()

    def _parse_result(self, payload: dict[str, Any]) -> StepResult[Any]:
        data = dict(payload.get("observation") or {})
        common = {"done": payload.get("done", False), "reward": payload.get("reward"),
                  "metadata": data.pop("metadata", None) or payload.get("metadata") or {}}
        observation: Any
        if "tools" in data:
            observation = ListToolsObservation(tools=data["tools"], **common)
        elif "tool_name" in data:
            observation = CallToolObservation(**data, **common)
        else:
            observation = HealthcareGymObservation(**data, **common)
        return StepResult(observation=observation, reward=payload.get("reward"), done=payload.get("done", False),
                          metadata=common["metadata"])

    def _parse_state(self, payload: dict[str, Any]) -> HealthcareGymState:
        return HealthcareGymState(**payload)

    def call_tool(self, tool_name: str, arguments: dict[str, Any] | None = None, *, message: str | None = "") -> Any:
        """Run a task tool with `arguments` (a dict, so a tool argument may be called anything, `name`
        included). `message`: the assistant text of the turn the call opens ("" for none); None adds
        the call to the open turn."""
        metadata: dict[str, Any] = {SAME_TURN_META_KEY: True} if message is None else {MESSAGE_META_KEY: message}
        return self.step(CallToolAction(tool_name=tool_name, arguments=dict(arguments or {}), metadata=metadata))

    def list_tools(self) -> Any:
        """The episode tools and the tools of the session's domain (before a reset: the first served domain's)."""
        return self.step(ListToolsAction())

    def finish(self, final_text: str | None = None, reason: str | None = None) -> Any:
        """End the episode: `final_text` is graded as the submitted answer; `reason` is a cut (e.g.
        "token_limit"). Idempotent: an ended episode answers its score."""
        arguments = {k: v for k, v in (("final_text", final_text), ("reason", reason)) if v is not None}
        return self.step(CallToolAction(tool_name="finish_episode", arguments=arguments))
