"""EHR reset and WRITE latency budgets (CPU time of the calling thread, so a loaded machine does not
make the test flaky): reset well under 10 ms, WRITE calls under 5 ms."""

from __future__ import annotations

import statistics
import time

import pytest

from envs import registry

registry.DOMAINS.setdefault("ehr_management", "envs.domains.ehr_management.environment")

from envs.core.task import Task  # noqa: E402
from envs.domains.ehr_management import build as ehr_build  # noqa: E402


@pytest.fixture(scope="module")
def m():
    ehr_build.build()
    import envs.domains.ehr_management.environment as module

    module.get_environment()  # the one-time index of db.json
    from envs.domains.clinical_diagnosis import knowledge

    knowledge.icd10_index()  # the one-time ICD-10-CM index behind lookup_icd10 / assign_icd10_code
    return module


def _cpu(fn, n: int) -> list[float]:
    out = []
    for i in range(n):
        c0 = time.thread_time()
        fn(i)
        out.append(time.thread_time() - c0)
    return sorted(out)


def test_reset_is_well_under_10_ms(m, monkeypatch):
    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    tasks = m.get_tasks()
    pool = [t for t in tasks if t.patient_id.startswith("EHR-")][:40] + [t for t in tasks if t.patient_id.startswith("SYN-")][:40]

    def reset(i: int) -> None:
        env = m.get_environment()
        env.on_reset(env, pool[i % len(pool)])
        assert list(env.db.patients) == [pool[i % len(pool)].patient_id]

    samples = _cpu(reset, 160)
    assert statistics.median(samples) < 0.002 and samples[int(0.95 * len(samples))] < 0.005


def test_write_calls_are_under_5_ms(m, monkeypatch):
    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    env = m.get_environment()
    env.on_reset(env, Task(ticket="x", patient_id="EHR-001"))
    writes = [("write_clinical_note", {"patient_id": "EHR-001", "note_type": "progress", "text": "Stable overnight on low-dose norepinephrine."}),
              ("place_order", {"patient_id": "EHR-001", "kind": "lab", "description": "lactate in 2 hours"}),
              ("escalate_care", {"patient_id": "EHR-001", "team": "icu_attending", "reason": "rising lactate despite fluids"}),
              ("discontinue_order", {"patient_id": "EHR-001", "order_id": "EHR-001-MED-2", "reason": "course complete"}),
              ("assign_icd10_code", {"patient_id": "EHR-001", "icd10_code": "A41.9"})]

    def write(i: int) -> None:
        name, args = writes[i]
        assert env.toolkit.call(name, args).ok

    samples = _cpu(write, len(writes))
    assert max(samples) < 0.005, samples
