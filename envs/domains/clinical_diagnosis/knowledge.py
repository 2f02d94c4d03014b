"""Read-only knowledge the clinical tools compute from, loaded once per process from the build folder:
the HPO phenotype index (plus the authored common-disease profiles), ICD-10-CM, the lab catalogue."""

from __future__ import annotations

import atexit
import gc
import json
from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.paths import domain_build_dir

from .hpo import PhenotypeIndex
from .icd10 import ICD10Index
from .labs import LabCatalog

DOMAIN = "clinical_diagnosis"


def build_file(name: str, domain: str = DOMAIN) -> Path:
    path = domain_build_dir(domain) / name
    if not path.exists():
        raise DataFileError(f"{path}: missing built knowledge file (run `hcgym data build {domain}`)")
    return path


def _frozen(obj):
    """Move the freshly loaded (large, immutable) index out of the garbage collector's scans, so
    later allocations in tools and resets do not pay for traversing millions of objects. At exit the
    objects are handed back to the collector, so extension modules loaded before the freeze (duckdb)
    see their objects released instead of reporting leaks."""
    gc.collect()
    gc.freeze()
    global _UNFREEZE_REGISTERED
    if not _UNFREEZE_REGISTERED:
        atexit.register(gc.unfreeze)
        _UNFREEZE_REGISTERED = True
    return obj


_UNFREEZE_REGISTERED = False


@lru_cache(maxsize=1)
def hpo_index() -> PhenotypeIndex:
    return _frozen(PhenotypeIndex(json.loads(build_file("hpo.json").read_text(encoding="utf-8"))))


@lru_cache(maxsize=1)
def icd10_index() -> ICD10Index:
    index = ICD10Index(json.loads(build_file("icd10cm.json").read_text(encoding="utf-8")))
    index.search("warm up")  # builds the word index now, not inside the first agent call
    return _frozen(index)


@lru_cache(maxsize=1)
def lab_catalog() -> LabCatalog:
    return LabCatalog(json.loads(build_file("lab_catalog.json").read_text(encoding="utf-8"))["analytes"])
