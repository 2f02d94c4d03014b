"""The rollout's tool server: one `HealthcareGymEnv` per rollout, its tools served over MCP.

verifiers launches this module (`python -m healthcare_gym.servers.tool`) once per rollout, fetches the
rollout's task and calls `setup_task`, which starts the task's episode. Every tool of the task is
served with the env's own schema (`env.tool_schemas` `parameters`, verbatim) and its arguments are
passed to `env.call_tool` as the model sent them, so the env validates them (an unknown argument or a
wrong type is the env's `invalid_arguments` result, recorded in the episode as in every other way to
run it). Each call is appended to the rollout's `EpisodeState`, which scoring replays
(`healthcare_gym.episode`).
"""

from __future__ import annotations

import inspect
from typing import TYPE_CHECKING, Any

import verifiers.v1 as vf
from pydantic import ConfigDict

from ..episode import EnvLimits, EpisodeState, RecordedCall

if TYPE_CHECKING:
    from mcp.server.mcpserver import MCPServer


class HealthcareGymToolsetConfig(vf.ToolsetConfig):
    """The tool server's config (`--env.taskset.task.tools.*`): where it runs (verifiers'
    `ToolsetConfig`) and the env's limits."""

    limits: EnvLimits = EnvLimits()


class HealthcareGymToolset(vf.Toolset[HealthcareGymToolsetConfig, EpisodeState]):
    """The task's tools, served bare (`submit_answer`, not `<server>_submit_answer`), as the env's
    policy and the tasks name them."""

    TOOL_PREFIX = None

    def __init__(self, config: HealthcareGymToolsetConfig) -> None:
        super().__init__(config)
        self.env = None

    async def setup_task(self, task: vf.TaskData) -> None:
        """Start the rollout's episode: the task's domain, split and id (`HealthcareGymData`)."""
        from envs.env import HealthcareGymEnv

        env = HealthcareGymEnv(domain=task.domain, split=task.split, **self.config.limits.env_kwargs())
        env.reset(options={"task_id": task.id})
        self.env = env

    def register(self, mcp: MCPServer) -> None:
        if self.env is None:
            raise RuntimeError("HealthcareGymToolset serves one rollout's task: verifiers calls setup_task "
                               "before register (run it as a task-scoped toolset, from Task.toolsets)")
        for schema in self.env.tool_schemas:
            function = schema["function"]
            # The SDK's ToolManager.add_tool returns the registered Tool, whose schema and argument
            # model are replaced below (MCPServer.add_tool returns nothing).
            handler = self._with_state(_handler(self, function["name"]))
            tool = mcp._tool_manager.add_tool(handler, name=function["name"],
                                              description=function.get("description") or "")
            # The model sees the env's schema verbatim, and the env (not the MCP SDK) validates
            # the arguments: the SDK's argument model would drop unknown keys and refuse wrong
            # types before the env could record the call.
            tool.parameters = function.get("parameters") or {"type": "object", "properties": {}}
            tool.fn_metadata = tool.fn_metadata.model_copy(update={"arg_model": _RawArguments})

    def call(self, name: str, arguments: dict[str, Any]) -> Any:
        """Run one call in the rollout's env and record it in the rollout's state."""
        import mcp_types as types

        result = self.env.call_tool(name, arguments, message="")
        state = self.state
        state.task_id = self.env.task.id
        state.calls.append(RecordedCall(name=name, arguments=arguments, observation=result.observation))
        return types.CallToolResult(content=[types.TextContent(type="text", text=result.observation)],
                                    is_error=not result.ok)


def _handler(server: HealthcareGymToolset, name: str):
    """A tool's handler. Its signature (one `arguments` dict) is only what the SDK builds an argument
    model from before `register` replaces that model with `_RawArguments`."""

    def call(arguments: dict) -> Any:
        return server.call(name, arguments)

    call.__name__ = call.__qualname__ = name
    call.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [inspect.Parameter("arguments", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=dict)])
    return call


def _raw_arguments_model():
    from mcp.server.mcpserver.utilities.func_metadata import ArgModelBase

    class RawArguments(ArgModelBase):
        """Every argument the model sent, untouched, for the env to validate."""

        model_config = ConfigDict(extra="allow", arbitrary_types_allowed=True)

        def model_dump_one_level(self) -> dict[str, Any]:
            return {"arguments": dict(self.model_extra or {})}

    return RawArguments


_RawArguments = _raw_arguments_model()


if __name__ == "__main__":
    HealthcareGymToolset.run()
