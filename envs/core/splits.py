"""Seeded train / test / validation splits for a domain's generated tasks (build time).

A domain's `build.py` picks one of three assignments and writes the result with
`envs.core.domain.write_split` (the `split_tasks.json` format: `{"train": [ids], "test": [ids],
"validation": [ids]}`, each list sorted):

- `round_robin_type_splits`: fixed held-out sizes, filled round-robin over task types so every
  held-out split covers every type (psychiatry, obstetrics, radiology_report, visual_diagnosis).
- `proportional_type_splits`: fixed held-out sizes, shared among task types in proportion to their
  counts (medical_qa).
- `grouped_splits`: per group, a fixed number of validation ids, then a fraction of the rest to
  test (clinical_diagnosis, triage_emergency, ehr_management).

The two type-stratified assignments then swap any held-out task that near-duplicates a training
task (`envs.core.contamination.find_leaks`) with a training task of the same type, so a held-out
score is not inflated by a memorised twin. Every assignment is a pure function of its inputs and
seed: a rebuild writes byte-identical split files.
"""

from __future__ import annotations

import random
from collections import defaultdict

from envs.core.contamination import find_leaks
from envs.core.task import Task

# Rounds of leak swapping before the build gives up (each round re-checks the swapped-in tasks).
_LEAK_SWAP_ROUNDS = 20


def _tasks_by_type(tasks: list[dict]) -> dict[str, list[str]]:
    by_type: dict[str, list[str]] = defaultdict(list)
    for t in tasks:
        by_type[t["description"]["task_type"]].append(t["id"])
    return by_type


def _swap_out_leaks(tasks: list[dict], splits: dict[str, list[str]], domain: str) -> dict[str, list[str]]:
    """Swap held-out tasks that near-duplicate a training task with clean training tasks of the same type."""
    objs = {t["id"]: Task.model_validate(t) for t in tasks}
    for _ in range(_LEAK_SWAP_ROUNDS):
        train = [objs[i] for i in splits["train"]]
        held = [objs[i] for s in ("test", "validation") for i in splits[s]]
        leaks = {leak.held_out_id for leak in find_leaks(train, held)}
        if not leaks:
            break
        for split in ("test", "validation"):
            for tid in [i for i in splits[split] if i in leaks]:
                tt = objs[tid].description.task_type
                swap = next((c for c in splits["train"] if objs[c].description.task_type == tt and c not in leaks), None)
                if swap is not None:
                    splits[split][splits[split].index(tid)] = swap
                    splits["train"][splits["train"].index(swap)] = tid
    else:
        raise ValueError(f"{domain}: could not remove near-duplicate leaks from the held-out splits")
    return {k: sorted(v) for k, v in splits.items()}


def round_robin_type_splits(tasks: list[dict], sizes: dict[str, int], seed: int, domain: str) -> dict[str, list[str]]:
    """`sizes["validation"]` then `sizes["test"]` ids taken round-robin over task types (a type keeps
    at least two tasks for train); the rest is train; near-duplicate leaks swapped out.

    Args:
        tasks: The generated tasks as dicts (each with `id` and `description.task_type`).
        sizes: Held-out sizes, keys "validation" and "test".
        seed: Seed of the per-type shuffle.
        domain: The domain name, for the error raised when leaks cannot be removed.
    """
    rng = random.Random(seed)
    by_type = _tasks_by_type(tasks)
    splits: dict[str, list[str]] = {"train": [], "test": [], "validation": []}
    order = sorted(by_type)
    quota = {s: n for s, n in sizes.items()}
    pools = {tt: sorted(ids) for tt, ids in by_type.items()}
    for ids in pools.values():
        rng.shuffle(ids)
    # Round-robin over types so every held-out split covers every type.
    for split in ("validation", "test"):
        k = 0
        while quota[split] > 0 and any(pools.values()):
            tt = order[k % len(order)]
            k += 1
            if pools[tt] and len(pools[tt]) > 2:
                splits[split].append(pools[tt].pop())
                quota[split] -= 1
            if k > 10000:
                break
    for ids in pools.values():
        splits["train"] += ids
    return _swap_out_leaks(tasks, splits, domain)


def proportional_type_splits(tasks: list[dict], sizes: dict[str, int], seed: int, domain: str) -> dict[str, list[str]]:
    """Held-out sizes shared among task types in proportion to their counts (the last type takes
    the remainder); the rest is train; near-duplicate leaks swapped out.

    Args:
        tasks: The generated tasks as dicts (each with `id` and `description.task_type`).
        sizes: Held-out sizes by split name, in the order they are taken from each type.
        seed: Seed of the per-type shuffle.
        domain: The domain name, for the error raised when leaks cannot be removed.
    """
    rng = random.Random(seed)
    by_type = _tasks_by_type(tasks)
    total = len(tasks)
    splits: dict[str, list[str]] = {"train": [], "test": [], "validation": []}
    remaining = dict(sizes)
    types = sorted(by_type)
    for i, tt in enumerate(types):
        ids = sorted(by_type[tt])
        rng.shuffle(ids)
        start = 0
        for split, size in sizes.items():
            if i == len(types) - 1:
                take = remaining[split]
            else:
                take = min(round(size * len(ids) / total), remaining[split])
            splits[split] += ids[start:start + take]
            remaining[split] -= take
            start += take
        splits["train"] += ids[start:]
    return _swap_out_leaks(tasks, splits, domain)


def grouped_splits(groups: dict[str, list[str]], validation: dict[str, int], test_fraction: float = 0.2,
                   seed: int = 23) -> dict[str, list[str]]:
    """Seeded per-group split: `validation[group]` ids, then test_fraction of the rest to test.

    Args:
        groups: Task ids by group (a task family, e.g. "triage_level").
        validation: Validation ids to take from each group (0 when absent).
        test_fraction: Share of each group's remaining ids that goes to test.
        seed: Seed of the per-group shuffle (one generator over the groups in sorted order).
    """
    rng = random.Random(seed)
    out: dict[str, list[str]] = {"train": [], "test": [], "validation": []}
    for group in sorted(groups):
        ids = sorted(groups[group])
        rng.shuffle(ids)
        n_val = validation.get(group, 0)
        val, rest = ids[:n_val], ids[n_val:]
        n_test = round(len(rest) * test_fraction)
        out["validation"] += sorted(val)
        out["test"] += sorted(rest[:n_test])
        out["train"] += sorted(rest[n_test:])
    return out
