"""The authored pathways of the cross-domain domain and the fixed train/test split.

`python -m envs.domains.cross_domain.authoring` writes `pathways.json` and `split_tasks.json`
next to the environment; the test suite checks that the committed files equal what this package
builds, so the JSON is never edited by hand.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from . import chest_pain, diabetic, paediatric, postop, sepsis, stroke

HERE = Path(__file__).resolve().parent.parent
MODULES = (chest_pain, diabetic, stroke, sepsis, postop, paediatric)
# One variant of each pathway is held out for test; every pathway keeps its other variants in train.
TEST_IDS: tuple[str, ...] = (
    "chest_pain_nstemi",
    "diabetic_emergency_hhs",
    "stroke_code_blood_pressure",
    "sepsis_bundle_cholangitis",
    "postop_haemorrhage",
    "paediatric_fever_pneumonia",
)


def all_pathways() -> list[dict[str, Any]]:
    out = [p for module in MODULES for p in module.pathways()]
    ids = [p["id"] for p in out]
    duplicates = sorted({i for i in ids if ids.count(i) > 1})
    if duplicates:
        raise ValueError(f"duplicate pathway ids: {duplicates}")
    return out


def splits(pathways: list[dict[str, Any]]) -> dict[str, list[str]]:
    ids = [f"pathway_{p['id']}" for p in pathways]
    test = [f"pathway_{i}" for i in TEST_IDS]
    unknown = [i for i in test if i not in ids]
    if unknown:
        raise ValueError(f"test split names unknown pathways: {unknown}")
    return {"train": [i for i in ids if i not in test], "test": test}


def render() -> dict[str, str]:
    """File name -> content of the two generated files."""
    pathways = all_pathways()
    return {
        "pathways.json": json.dumps(pathways, indent=1, ensure_ascii=False) + "\n",
        "split_tasks.json": json.dumps(splits(pathways), indent=1) + "\n",
    }


def write(folder: Path = HERE) -> list[Path]:
    written = []
    for name, text in render().items():
        path = folder / name
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written
