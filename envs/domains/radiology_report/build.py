"""Build the radiology-report database and generated tasks under `domain_build_dir("radiology_report")`.

    build(offline=False, force=False) -> dict

Inputs: our synthetic studies (`generate.py`, seeded), our authored studies
(`studies_authored.json`) and report templates (`templates.json`). Report-workflow tasks carry the
expected final database state (`expected_db_hash`), computed by replaying their expected actions
on a fresh database. Deterministic; skipped when the inputs are unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path

from envs.core import splits as split_helpers
from envs.core.domain import inputs_fingerprint, skip_if_built, write_manifest, write_task_dicts
from envs.core.paths import domain_build_dir
from envs.domains.radiology_report import generate as G
from envs.domains.radiology_report.data_model import RadiologyDB, ReportTemplate, Study
from envs.domains.radiology_report.tools import RadiologyTools

HERE = Path(__file__).parent
NAME = "radiology_report"
SEED = 5150
SPLIT_SIZES = {"validation": 10, "test": 32}


def _fingerprint() -> str:
    files = [HERE / name for name in ("build.py", "generate.py", "tools.py", "data_model.py", "templates.json",
                                      "studies_authored.json", "tasks.json")]
    return inputs_fingerprint(files + [Path(split_helpers.__file__)])  # + the shared split assignment


def expected_hash(db: RadiologyDB, task: dict) -> str:
    """Replay a task's expected actions on a fork of the database; the resulting content hash."""
    tools = RadiologyTools(db.fork())
    for a in task["evaluation_criteria"]["actions"]:
        outcome = tools.call(a["name"], a["arguments"])
        if outcome.error:
            raise ValueError(f"{task['id']}: expected action {a['name']} fails: {outcome.error}")
    return tools.db.content_hash()


def build(offline: bool = False, force: bool = False) -> dict:
    out = domain_build_dir(NAME)
    fingerprint = _fingerprint()
    if (done := skip_if_built(out, fingerprint, force)) is not None:
        return done
    templates = {k: ReportTemplate(key=k, **v) for k, v in json.loads((HERE / "templates.json").read_text())["templates"].items()}
    studies, tasks = G.generate(SEED, {k: t.critical_categories for k, t in templates.items()})
    authored = [Study.model_validate(s) for s in json.loads((HERE / "studies_authored.json").read_text(encoding="utf-8"))]
    all_studies = {s.study_id: s for s in [*studies, *authored]}
    if len(all_studies) != len(studies) + len(authored):
        raise ValueError("radiology_report: duplicate study ids between generated and authored studies")
    db = RadiologyDB(studies=all_studies, templates=templates)
    db.dump(out / "db.json")
    for t in tasks:
        if t["description"]["task_type"] == "report_workflow":
            t["evaluation_criteria"]["expected_db_hash"] = expected_hash(db, t)
            t["evaluation_criteria"]["reward_basis"] = [*t["evaluation_criteria"]["reward_basis"], "DB"]
    splits = split_helpers.round_robin_type_splits(tasks, SPLIT_SIZES, SEED, NAME)
    summary = {"studies": len(all_studies), **write_task_dicts(out, tasks, splits)}
    write_manifest(out, fingerprint, summary, ["db.json", "tasks.json", "split_tasks.json"])
    return summary
