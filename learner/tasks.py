"""Training tasks: which tasks a run uses, the order it visits them in, and each episode's seed.

Everything here is a pure function of (config, seed, position), so a resumed run visits the same
tasks with the same seeds as the run it continues.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from actors.agent_loop import AgentLoop, EpisodeSpec


@dataclass(frozen=True)
class TaskRef:
    domain: str
    task_id: str
    split: str | None


def load_task_refs(domains: list[str], split: str | None, limit: int | None = None,
                   pattern: str | None = None) -> list[TaskRef]:
    """Task references of a split over domains, in a stable order (domain, then file order).

    Args:
        domains: Registered domain names.
        split: The split ("train", "test", ...).
        limit: Keep the first `limit` references.
        pattern: Keep only task ids matching this regular expression.
    """
    from envs import registry

    refs: list[TaskRef] = []
    for domain in domains:
        if domain not in registry.list_domains():
            raise ValueError(f"data.domains: unknown domain {domain!r}; registered: {registry.list_domains()}")
        tasks = registry.get_tasks(domain, split)
        if not tasks:
            raise ValueError(f"data: domain {domain!r} has no tasks in split {split!r} (run `hcgym data build`?)")
        refs.extend(TaskRef(domain, t.id, split) for t in tasks if pattern is None or re.search(pattern, t.id))
    if not refs:
        raise ValueError(f"data: no task of {domains} in split {split!r} matches task_id_pattern {pattern!r}")
    return refs[:limit] if limit else refs


def prompt_lengths(refs: list[TaskRef], loop: AgentLoop) -> list[int]:
    """Token length of each task's rendered prompt (system prompt + ticket), as the agent loop renders it."""
    from envs import registry
    from envs.env import prompt_parts

    domain_envs: dict[str, Any] = {}
    tasks: dict[tuple[str, str | None], dict[str, Any]] = {}
    out = []
    for ref in refs:
        if ref.domain not in domain_envs:
            domain_envs[ref.domain] = registry.get_environment(ref.domain)
        key = (ref.domain, ref.split)
        if key not in tasks:
            tasks[key] = {t.id: t for t in registry.get_tasks(ref.domain, ref.split)}
        parts = prompt_parts(domain_envs[ref.domain], tasks[key][ref.task_id])
        out.append(len(loop.render_prompt(parts)))
    return out


def select_tasks(domains: list[str], split: str, limit: int | None, pattern: str | None, *, what: str,
                 loop: AgentLoop, max_prompt_tokens: int | None, log: Callable[[str], None]) -> list[TaskRef]:
    """The tasks of a split a run uses: `load_task_refs`, minus prompts longer than `max_prompt_tokens`
    (None keeps them all). `what` ("train", "validation") names the set in messages."""
    refs = load_task_refs(domains, split, limit, pattern)
    if max_prompt_tokens is not None:
        lengths = prompt_lengths(refs, loop)
        kept = [r for r, n in zip(refs, lengths) if n <= max_prompt_tokens]
        if len(kept) < len(refs):
            log(f"[setup] dropped {len(refs) - len(kept)} {what} tasks whose prompt exceeds "
                f"rollout.max_prompt_tokens={max_prompt_tokens}")
        refs = kept
    if not refs:
        raise ValueError(f"no {what} tasks left in split {split!r} of {domains}")
    return refs


class TaskSampler:
    """Epoch-wise shuffles of the training tasks, deterministic in (seed, epoch); resumable."""

    def __init__(self, refs: list[TaskRef], seed: int) -> None:
        if not refs:
            raise ValueError("no training tasks")
        self.refs = refs
        self.seed = seed
        self.epoch = 0
        self.position = 0
        self._order = self._permutation(0)

    def _permutation(self, epoch: int) -> list[int]:
        return np.random.default_rng([self.seed, epoch]).permutation(len(self.refs)).tolist()

    def next(self) -> TaskRef:
        if self.position >= len(self._order):
            self.epoch += 1
            self.position = 0
            self._order = self._permutation(self.epoch)
        ref = self.refs[self._order[self.position]]
        self.position += 1
        return ref

    def state_dict(self) -> dict[str, int]:
        return {"epoch": self.epoch, "position": self.position}

    def load_state_dict(self, state: dict[str, int]) -> None:
        self.epoch, self.position = int(state["epoch"]), int(state["position"])
        self._order = self._permutation(self.epoch)


def episode_seed(run_seed: int, *parts: Any) -> int:
    digest = hashlib.blake2b(":".join(str(p) for p in (run_seed, *parts)).encode(), digest_size=4).digest()
    return int.from_bytes(digest, "little") & 0x7FFF_FFFF


def episode_specs(run_seed: int, seq: int, task: TaskRef, version: int, size: int, tag: str = "",
                  greedy: bool = False) -> list[EpisodeSpec]:
    """The `size` episodes of group `seq` on `task`; seeds depend only on (run seed, tag, seq, index),
    so a re-admitted group (after a resume) gets the same seeds."""
    specs = []
    for i in range(size):
        seed = episode_seed(run_seed, tag, seq, i)
        specs.append(EpisodeSpec(
            sample_id=f"{task.task_id}:{tag}{i}:{seed}", task_id=task.task_id, domain=task.domain,
            split=task.split, group_id=f"{tag}g{seq:06d}:{task.task_id}", group_index=i, seed=seed,
            min_version=version, greedy=greedy,
        ))
    return specs
