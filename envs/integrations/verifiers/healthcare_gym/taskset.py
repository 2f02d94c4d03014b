"""HealthcareGym as a verifiers v1 environment: a taskset over one domain's tasks, the task's tools
served per rollout by `HealthcareGymToolset`, and the env's own 5D reward as the score.

- `HealthcareGymTaskset` loads the rows `hcgym tasks export` writes (`envs.export.task_rows`): the
  domain policy as the system prompt, the ticket as the user prompt, the grading metadata in
  `answer` (never shown to the model).
- Each rollout's tools run in its own `HealthcareGymEnv` (`servers/tool.py`).
- Scoring (`HealthcareGymTask.finalize`) rebuilds the episode from the calls the server ran and ends
  it through `env.finish` (`episode.py`): a final text reply is graded as the answer, a rollout
  verifiers cut at its turn (or token) limit gets the env's truncation score, an episode that
  `submit_answer` ended keeps its score. The reward `total` is the env's total; the metrics are the
  env's reward components (accuracy, process, safety, format, coherence, and `assertion` where the
  task has assertions), `is_correct`, `truncated` and `tool_calls`.
- `HealthcareGymEnvironment` is the package's env: the single agent seat on verifiers' `null` harness
  (the task's tools and nothing else: no shell) in a local subprocess, at most `DEFAULT_MAX_TURNS`
  model turns.
"""

from __future__ import annotations

import base64
import mimetypes
from pathlib import Path

import verifiers.v1 as vf

from .episode import EpisodeState, cut_reason, replay_episode
from .servers.tool import HealthcareGymToolset, HealthcareGymToolsetConfig

#: Model turns per rollout unless `--env.agent.max-turns` says otherwise.
DEFAULT_MAX_TURNS = 10


class HealthcareGymData(vf.TaskData):
    """One exported task row (`envs.export.TaskRow`): `id` is the task id.

    Attributes:
        domain: The task's domain.
        split: The split it belongs to.
        answer: The grading metadata as JSON text (answer type, correct answer, aliases, ...): for
            analysis; the env grades with its own copy, and it is never in the prompt.
        image_path: The task's image (sent to the model as an image part), else None.
    """

    domain: str
    split: str
    answer: str
    image_path: str | None = None


class HealthcareGymTaskConfig(vf.TaskConfig):
    """`--env.taskset.task.*`: the tool server's placement and the env's limits (`tools.limits`)."""

    tools: HealthcareGymToolsetConfig = HealthcareGymToolsetConfig()


class HealthcareGymTask(vf.Task[HealthcareGymData, EpisodeState, HealthcareGymTaskConfig]):
    """One clinical task: its tools (a server per rollout) and the env's score."""

    @property
    def key(self) -> str:
        return f"{self.data.domain}/{self.data.id}"

    @classmethod
    def toolsets(cls, config: HealthcareGymTaskConfig) -> list[vf.Toolset]:
        return [HealthcareGymToolset(config.tools)]

    async def finalize(self, trace: vf.Trace) -> None:
        """End the rollout's episode (`episode.replay_episode`) and keep the end on the trace."""
        state: EpisodeState = trace.state
        if state.task_id not in (None, self.data.id):
            raise ValueError(f"the tool server ran task {state.task_id!r}, "
                             f"the rollout is task {self.data.id!r}")
        # In the event loop, not a worker thread: the env's scorers are not written to be thread-safe
        # (their graders load lazily into module caches on a process's first score).
        end = replay_episode(domain=self.data.domain, split=self.data.split, task_id=self.data.id,
                             calls=state.calls, limits=self.config.tools.limits,
                             final_text=trace.last_reply, cut=cut_reason(trace))
        state.end = end
        # The trace's state is not written to traces.jsonl; the end and the env's calls are.
        trace.info["healthcare_gym"] = {
            "end_reason": end.reason, "submitted_answer": end.submitted_answer, "reward": end.reward,
            "reward_components": end.reward_components, "is_correct": end.is_correct,
            "safety_violations": end.safety_violations, "grader_error": end.grader_error,
            "calls": [call.model_dump(mode="json") for call in state.calls]}

    @staticmethod
    def _end(trace: vf.Trace):
        end = trace.state.end
        if end is None:
            raise ValueError("the episode has no end: HealthcareGymTask.finalize did not run before scoring")
        return end

    @vf.reward
    async def total(self, trace: vf.Trace) -> float:
        """The env's reward: the weighted total of its dimensions."""
        return self._end(trace).reward

    @vf.metric
    async def dimensions(self, trace: vf.Trace) -> dict[str, float]:
        """The env's reward components, each its own metric."""
        return {name: value for name, value in self._end(trace).reward_components.items() if name != "total"}

    @vf.metric
    async def outcome(self, trace: vf.Trace) -> dict[str, float]:
        end = self._end(trace)
        return {"is_correct": float(end.is_correct), "truncated": float(end.truncated),
                "tool_calls": float(len(trace.state.calls))}


class HealthcareGymTasksetConfig(vf.TasksetConfig):
    """`--env.taskset.*`: which tasks load."""

    domain: str = "drug_interaction"
    """A registered domain (`hcgym tasks list`)."""
    split: str | None = None
    """One of the domain's splits; None loads every split."""
    task: HealthcareGymTaskConfig = HealthcareGymTaskConfig()


class HealthcareGymTaskset(vf.Taskset[HealthcareGymTask, HealthcareGymTasksetConfig]):
    """One domain's tasks (one split or all), in the registry's order."""

    def load(self):
        from envs.export import task_rows

        for row in task_rows(self.config.domain, self.config.split):
            system, user = row.prompt
            prompt: str | list[vf.UserMessage] = user["content"]
            if row.image_path:
                prompt = [vf.UserMessage(content=[vf.TextContentPart(text=user["content"]),
                                                  vf.ImageUrlContentPart(image_url=vf.ImageUrlSource(
                                                      url=_data_url(row.image_path)))])]
            yield HealthcareGymTask(
                HealthcareGymData(id=row.task_id, name=row.task_id, domain=row.domain, split=row.split,
                                  system_prompt=system["content"], prompt=prompt, answer=row.answer,
                                  image_path=row.image_path),
                self.config.task)


def _data_url(path: str) -> str:
    mime = mimetypes.guess_type(path)[0] or "image/png"
    return f"data:{mime};base64,{base64.b64encode(Path(path).read_bytes()).decode()}"


class HealthcareGymEnvConfig(vf.EnvConfig):
    agent: vf.AgentConfig = vf.AgentConfig(harness={"id": "null"}, runtime=vf.SubprocessConfig(),
                                           max_turns=DEFAULT_MAX_TURNS)
    """The one seat. `null` harness: the model gets the task's tools only; it executes no code, so
    a local subprocess is its runtime."""


class HealthcareGymEnvironment(vf.Env[HealthcareGymEnvConfig]):
    """The single-agent env with the seat's defaults above (`vf.SingleAgentEnv`'s episode)."""

    async def run(self, task: HealthcareGymTask, agents: vf.Agents) -> None:
        await agents.agent.run(task)
