"""Contamination check: no test (or validation) task may appear in train.

Two tests per held-out task against every training task:
  * exact: the normalised text (lower case, punctuation and whitespace collapsed) of ticket +
    options is identical;
  * near-duplicate: the Jaccard similarity of word 5-gram shingles is >= `threshold` (0.8), the gold
    answers agree and the case material is the same (same patient record and image, or none):
    templated generators legitimately produce tickets that differ in one entity or point at a
    different patient's chart; the same answer to a near-identical question about the same case
    is what leaks.
Candidates come from an inverted index over shingles, so the check is linear in practice.
"""

from __future__ import annotations

import re
import unicodedata
from collections import defaultdict
from dataclasses import dataclass

from envs.core.task import Task

_NON_WORD = re.compile(r"[^\w]+", re.UNICODE)


def normalise(text: str) -> str:
    text = unicodedata.normalize("NFKC", text).lower()
    return " ".join(_NON_WORD.sub(" ", text).split())


def task_text(task: Task) -> str:
    options = " ".join(f"{k} {v}" for k, v in sorted((task.options or {}).items()))
    return normalise(f"{task.ticket} {options}")


def shingles(text: str, n: int = 5) -> frozenset[int]:
    words = text.split()
    if len(words) < n:
        return frozenset({hash(text)})
    return frozenset(hash(" ".join(words[i:i + n])) for i in range(len(words) - n + 1))


@dataclass
class Leak:
    held_out_id: str
    train_id: str
    kind: str  # "exact" or "near"
    similarity: float


def find_leaks(train: list[Task], held_out: list[Task], threshold: float = 0.8) -> list[Leak]:
    exact: dict[str, str] = {}
    index: dict[int, list[int]] = defaultdict(list)
    train_shingles: list[frozenset[int]] = []
    for i, task in enumerate(train):
        text = task_text(task)
        exact.setdefault(text, task.id)
        sh = shingles(text)
        train_shingles.append(sh)
        for s in sh:
            index[s].append(i)
    leaks: list[Leak] = []
    for task in held_out:
        text = task_text(task)
        if text in exact:
            leaks.append(Leak(task.id, exact[text], "exact", 1.0))
            continue
        sh = shingles(text)
        counts: dict[int, int] = defaultdict(int)
        for s in sh:
            for i in index.get(s, ()):
                counts[i] += 1
        for i, shared in counts.items():
            union = len(sh) + len(train_shingles[i]) - shared
            similarity = shared / union if union else 0.0
            other = train[i]
            if (other.patient_id, other.image_path) != (task.patient_id, task.image_path):
                continue
            if similarity >= threshold and (other.correct_answer or "").strip().lower() == (task.correct_answer or "").strip().lower():
                leaks.append(Leak(task.id, other.id, "near", similarity))
                break
    return leaks
