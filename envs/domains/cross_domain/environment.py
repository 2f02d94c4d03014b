"""The cross-domain pathway domain: each task is a pathway run as one episode.

The episode's toolkit is a `PathwayEngine` built at reset for the task's pathway, over fresh
environments of every domain the pathway touches, with the pathway's patient inserted into each
(`add_patient(domain_env, record)` of that domain's environment module). The reward is the
pathway score (per phase and overall, see `score_pathway`) with the 5D reward's safety penalties
and critical cap applied on top.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment, read_policy
from envs.core.task import ExpectedAction, Task
from envs.domains.cross_domain.pathway import Pathway, PathwayEngine

HERE = Path(__file__).parent
PATHWAY_FILE = HERE / "pathways.json"
# Final-answer weight in the overall pathway score; the rest is the mean phase score.
FINAL_ANSWER_WEIGHT = 0.2


@lru_cache(maxsize=4)
def load_pathways(path: Path = PATHWAY_FILE) -> dict[str, Pathway]:
    if not path.exists():
        raise DataFileError(f"{path}: pathway file not found")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}: not valid JSON at line {exc.lineno}: {exc.msg}") from None
    out: dict[str, Pathway] = {}
    for index, item in enumerate(raw):
        try:
            pathway = Pathway.model_validate(item)
        except Exception as exc:
            raise DataFileError(f"{path} [pathway #{index} {item.get('id')!r}]: {exc}") from None
        out[pathway.id] = pathway
    return out


def pathway_task(pathway: Pathway) -> Task:
    actions: list[ExpectedAction] = []
    for phase in pathway.phases:
        actions += phase.required_actions
        if phase.transition == "agent_declares":  # the gold solution ends such a phase itself
            actions.append(ExpectedAction(name="complete_phase", arguments={"summary": f"{phase.name} complete"},
                                          compare_args=[], info=f"declare the end of phase {phase.name!r}"))
    assertions = [s for phase in pathway.phases for s in phase.nl_assertions]
    # the reference rationale submitted with the gold answer (envs.validate.gold_replay): each phase's
    # statement, in phase order, so the gold meets the assertions about what the clinician says or plans
    reasoning = "\n".join(p.gold_reasoning.strip() for p in pathway.phases
                          if p.gold_reasoning.strip())
    phases = " -> ".join(f"{p.name} ({p.domain})" for p in pathway.phases)
    ticket = (f"{pathway.presentation}\n\nThis is a multi-phase clinical pathway: {phases}. Work through each "
              f"phase with its tools; the next phase starts when the current one is complete (call "
              f"get_pathway_status at any time). At the end: {pathway.final_question}")
    return Task(
        id=f"pathway_{pathway.id}", domain="cross_domain", ticket=ticket, patient_id=pathway.patient_id,
        correct_answer=pathway.final_answer, answer_type="exact", answer_aliases=pathway.answer_aliases,
        emergency=pathway.emergency,
        description={"source": "authored:pathway", "task_type": "pathway", "category": pathway.title,
                     "provenance": {"guideline": pathway.guideline} if pathway.guideline else {}},
        evaluation_criteria={"actions": [a.model_dump() for a in actions], "nl_assertions": assertions,
                             "reward_basis": ["ACTION", "NL_ASSERTION", "ANSWER"]},
        metadata={"pathway_id": pathway.id, **({"gold_reasoning": reasoning} if reasoning else {})},
    )


def add_patient_hook(domain: str):
    """A domain's `add_patient(domain_env, record)`: from its `pathway_hooks` module if it has one,
    else from its environment module."""
    import importlib

    from envs import registry

    package = registry.DOMAINS[domain].rsplit(".", 1)[0]
    for module_name in (f"{package}.pathway_hooks", registry.DOMAINS[domain]):
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        if hasattr(module, "add_patient"):
            return module.add_patient
    raise DataFileError(f"domain {domain!r} has no add_patient hook (pathway_hooks.add_patient)")


def _imported_toolkit():
    """The toolkit of an imported cross-domain task (`hcgym tasks import`, no pathway): think, submit_answer
    and the shared knowledge tools, which is what the reference's cross-domain task files call."""
    from envs.core.common_tools import BaseDomainTools
    from envs.shared import shared_toolkits
    from envs.core.tools import CompositeToolkit

    return CompositeToolkit(BaseDomainTools(None), *shared_toolkits())


def _reset(domain_env: DomainEnvironment, task: Task, pathways: dict[str, Pathway] | None = None) -> None:
    from envs import registry

    if "pathway_id" not in task.metadata:  # an imported task, not a pathway
        domain_env.toolkit = _imported_toolkit()
        return
    pathway = (pathways or load_pathways())[task.metadata["pathway_id"]]
    envs_by_domain: dict[str, DomainEnvironment] = {}
    for domain in dict.fromkeys(p.domain for p in pathway.phases):
        env = registry.get_environment(domain)
        record = pathway.patients.get(domain)
        if record is not None:
            add_patient_hook(domain)(env, record)
        envs_by_domain[domain] = env
    engine = PathwayEngine(pathway, envs_by_domain)
    domain_env.toolkit = engine
    domain_env.scorer = lambda trajectory, t, weights, context: score_pathway(engine, trajectory, t, weights, context)
    first = envs_by_domain[pathway.phases[0].domain]
    domain_env.safety_context = first.safety_context
    domain_env.extras["engine"] = engine


def score_pathway(engine: PathwayEngine, trajectory: Any, task: Task, weights: Any, context: Any):
    """Overall = (1 - w) * mean phase score + w * final-answer accuracy, then the 5D reward's
    safety penalties and critical cap. Per-phase scores go to `details["pathway_phases"]`."""
    from envs.rewards import score_episode

    base = score_episode(trajectory, task, weights=weights, context=context)
    phases = engine.phase_scores()
    mean_phase = sum(p["score"] for p in phases) / len(phases)
    overall = (1 - FINAL_ANSWER_WEIGHT) * mean_phase + FINAL_ANSWER_WEIGHT * base.accuracy
    total = min(1.0, max(0.0, overall - base.penalty))
    if base.capped:
        total = min(total, base.total)
    details = {**base.details, "pathway_phases": phases, "pathway_overall": overall, "five_d_total": base.total}
    return base.model_copy(update={"total": total, "details": details})


def task_tool_definitions(task: Task) -> dict[str, Any]:
    """The tool definitions a pathway task's expected actions are checked against (`validate_task`):
    the control tools plus, for each required action, the tool of its own phase's domain. The
    environment's pre-reset toolkit has only the control tools, because the phase tools are built at
    reset; use this with `envs.validate.validate_task(task, "cross_domain", definitions)`."""
    from envs import registry
    from envs.domains.cross_domain.pathway import PathwayControlTools

    if "pathway_id" not in task.metadata:
        return dict(_imported_toolkit().definitions)
    pathway = load_pathways()[task.metadata["pathway_id"]]
    definitions: dict[str, Any] = dict(PathwayControlTools(None).definitions)
    toolkits: dict[str, Any] = {}
    for phase in pathway.phases:
        if phase.domain not in toolkits:
            toolkits[phase.domain] = registry.get_environment(phase.domain).toolkit.definitions
        for action in phase.required_actions:
            own = toolkits[phase.domain].get(action.name)
            if own is None:
                continue  # validate_task reports the unknown tool
            other = definitions.setdefault(action.name, own)
            if other.parameters != own.parameters:
                raise DataFileError(f"pathway {pathway.id!r}: tool {action.name!r} is required in two phases with "
                                    f"different signatures")
    return definitions


def coherence_records(task: Task) -> dict[str, dict[str, Any]]:
    """The patient record a pathway task puts into each domain it touches ({domain: record}): what
    `envs.coherence.check_tasks` checks against those domains' rules (a pathway has no `db.json`)."""
    pathway = load_pathways().get(str((task.metadata or {}).get("pathway_id")))
    return dict(pathway.patients) if pathway else {}


def get_environment() -> DomainEnvironment:
    from envs.domains.cross_domain.pathway import PathwayControlTools

    env = DomainEnvironment(name="cross_domain", policy=read_policy(HERE), toolkit=PathwayControlTools(None),
                            on_reset=_reset)
    return env


def imported_tasks() -> list[Task]:
    """Tasks converted into this domain by `hcgym tasks import` (split 'imported')."""
    from envs.core.domain import imported_tasks_dir
    from envs.core.task import load_tasks

    folder = imported_tasks_dir("cross_domain")
    return [t for f in sorted(folder.glob("*.json")) for t in load_tasks(f, domain="cross_domain")] \
        if folder.is_dir() else []


def get_tasks(split: str | None = None) -> list[Task]:
    tasks = [pathway_task(p) for p in load_pathways().values()] + imported_tasks()
    if split is None:
        return tasks
    splits = get_splits()
    if split not in splits:
        raise KeyError(f"domain 'cross_domain' has no split {split!r} (available: {sorted(splits)})")
    wanted = set(splits[split])
    return [t for t in tasks if t.id in wanted]


def get_splits() -> dict[str, list[str]]:
    path = HERE / "split_tasks.json"
    imported = [t.id for t in imported_tasks()]
    if path.exists():
        return json.loads(path.read_text(encoding="utf-8")) | ({"imported": imported} if imported else {})
    ids = sorted(f"pathway_{p}" for p in load_pathways())
    return {"train": ids[: max(1, len(ids) * 3 // 4)], "test": ids[max(1, len(ids) * 3 // 4):]} | (
        {"imported": imported} if imported else {})
