"""Build the visual-diagnosis images, database and generated tasks under `domain_build_dir("visual_diagnosis")`.

    build(offline=False, force=False) -> dict

Renders every study to `images/<study_id>.png` (numpy + the minimal PNG writer), keeps a study
only when the pixel analysis recovers its specification, writes `db.json` (studies, reference
archive, glossary of signs), `tasks.json` and `split_tasks.json`. All inputs are ours (seeded
code, `signs.json`, the authored cases `cases/*.json`); deterministic; skipped when unchanged.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from envs.core import splits as split_helpers
from envs.core.domain import inputs_fingerprint, skip_if_built, write_manifest, write_task_dicts
from envs.core.paths import domain_build_dir
from envs.domains.visual_diagnosis import generate as G
from envs.domains.visual_diagnosis.data_model import ImagingSign, Study, VisualDB

HERE = Path(__file__).parent
NAME = "visual_diagnosis"
SEED = 8080
SPLIT_SIZES = {"validation": 37, "test": 60}


def _fingerprint() -> str:
    files = [HERE / name for name in ("build.py", "generate.py", "render.py", "analysis.py", "png.py", "data_model.py",
                                      "signs.json", "case_schema.py")]
    cases = sorted((HERE / "cases").glob("*.json"))  # the authored cases
    return inputs_fingerprint(files + cases + [Path(split_helpers.__file__)])  # + the shared split assignment


def build(offline: bool = False, force: bool = False) -> dict:
    out = domain_build_dir(NAME)
    fingerprint = _fingerprint()
    if (done := skip_if_built(out, fingerprint, force)) is not None:
        return done
    if (out / "images").exists():
        shutil.rmtree(out / "images")
    studies, archive, tasks = G.generate(SEED, out)
    a_studies, a_tasks = G.authored(out)
    all_studies = {s.study_id: s for s in [*studies, *a_studies]}
    if len(all_studies) != len(studies) + len(a_studies):
        raise ValueError("visual_diagnosis: duplicate study ids")
    signs = {k: ImagingSign(term=k, **v) for k, v in json.loads((HERE / "signs.json").read_text())["signs"].items()}
    VisualDB(studies=all_studies, archive=archive, signs=signs).dump(out / "db.json")
    splits = split_helpers.round_robin_type_splits(tasks, SPLIT_SIZES, SEED, NAME)
    ids = [t["id"] for t in a_tasks]
    splits["train"] = sorted(splits["train"] + [i for k, i in enumerate(ids) if k % 3 != 1])
    splits["test"] = sorted(splits["test"] + [i for k, i in enumerate(ids) if k % 3 == 1])
    summary = {"studies": len(all_studies), "images": len(list((out / "images").glob("*.png"))), "archive_cases": len(archive),
               **write_task_dicts(out, [*tasks, *a_tasks], splits)}
    write_manifest(out, fingerprint, summary, ["db.json", "tasks.json", "split_tasks.json"])
    return summary
