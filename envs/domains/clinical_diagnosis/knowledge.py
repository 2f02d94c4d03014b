"""Read-only knowledge the clinical tools compute from, loaded once per process from the build folder:
the HPO phenotype index (plus the authored common-disease profiles), ICD-10-CM, the lab catalogue."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.frozen import frozen
from envs.core.icd10 import ICD10Index, built_icd10_index
from envs.core.paths import domain_build_dir

from .hpo import PhenotypeIndex
from .labs import LabCatalog

DOMAIN = "clinical_diagnosis"


def build_file(name: str, domain: str = DOMAIN) -> Path:
    path = domain_build_dir(domain) / name
    if not path.exists():
        raise DataFileError(f"{path}: missing built knowledge file (run `hcgym data build {domain}`)")
    return path


@lru_cache(maxsize=1)
def hpo_index() -> PhenotypeIndex:
    return frozen(PhenotypeIndex(json.loads(build_file("hpo.json").read_text(encoding="utf-8"))))


@lru_cache(maxsize=1)
def icd10_index() -> ICD10Index:
    return built_icd10_index(DOMAIN)


@lru_cache(maxsize=1)
def lab_catalog() -> LabCatalog:
    return LabCatalog(json.loads(build_file("lab_catalog.json").read_text(encoding="utf-8"))["analytes"])
