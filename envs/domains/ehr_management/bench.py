"""Reset and tool-call latency of the EHR domain: `python -m envs.domains.ehr_management.bench`.

Measures, after the one-time per-process index of `db.json`:
* reset: `get_environment()` + `on_reset` (open the task's chart) for ICU and Synthea patients;
* WRITE calls (the toolkit snapshots the database before each) and a few READ calls;
and prints median / p95 in milliseconds.
"""

from __future__ import annotations

import argparse
import statistics
import time


def _ms(samples: list[tuple[float, float]]) -> str:
    """Wall-clock median/p95 and CPU-time p95 (the CPU time of this thread excludes waiting for a core on
    a loaded machine)."""
    wall = sorted(w for w, _ in samples)
    cpu = sorted(c for _, c in samples)
    p95 = int(0.95 * (len(wall) - 1))
    return (f"wall median {statistics.median(wall) * 1e3:.3f} ms, p95 {wall[p95] * 1e3:.3f} ms; "
            f"CPU p95 {cpu[p95] * 1e3:.3f} ms, max {cpu[-1] * 1e3:.3f} ms (n={len(wall)})")


def main(argv: list[str] | None = None) -> dict[str, str]:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=200, help="repetitions per measurement")
    args = parser.parse_args(argv)

    from envs.core.task import Task

    from . import environment as m

    m.shared_toolkits = lambda: []  # the domain's own cost (the shared KB tools are measured elsewhere)
    started = time.perf_counter()
    m.get_environment()
    first = time.perf_counter() - started
    tasks = m.get_tasks()
    icu = [t for t in tasks if (t.patient_id or "").startswith("EHR-")]
    syn = [t for t in tasks if (t.patient_id or "").startswith("SYN-")]
    out = {"first get_environment (indexes db.json)": f"{first * 1e3:.1f} ms"}

    def reset(pool: list[Task]) -> list[tuple[float, float]]:
        samples = []
        for i in range(args.n):
            task = pool[i % len(pool)]
            t0, c0 = time.perf_counter(), time.thread_time()
            env = m.get_environment()
            env.on_reset(env, task)
            samples.append((time.perf_counter() - t0, time.thread_time() - c0))
        return samples

    out["reset, ICU patient"] = _ms(reset(icu))
    out["reset, Synthea patient"] = _ms(reset(syn))

    def calls(pid: str, name: str, make_args, fresh_every: int = 5) -> list[tuple[float, float]]:
        """Time one tool call; a fresh episode every `fresh_every` calls (an episode makes a few calls)."""
        samples = []
        env = None
        for i in range(args.n):
            if i % fresh_every == 0:
                env = m.get_environment()
                env.on_reset(env, Task(ticket="bench", patient_id=pid))
            a = make_args(i)
            t0, c0 = time.perf_counter(), time.thread_time()
            outcome = env.toolkit.call(name, a)
            samples.append((time.perf_counter() - t0, time.thread_time() - c0))
            assert outcome.ok, outcome.error
        return samples

    out["WRITE write_clinical_note (ICU chart)"] = _ms(calls(
        "EHR-001", "write_clinical_note",
        lambda i: {"patient_id": "EHR-001", "note_type": "progress", "text": f"Progress note number {i}: stable."}))
    out["WRITE place_order (ICU chart)"] = _ms(calls(
        "EHR-010", "place_order",
        lambda i: {"patient_id": "EHR-010", "kind": "lab", "description": f"basic metabolic panel #{i}"}))
    out["WRITE escalate_care (ICU chart)"] = _ms(calls(
        "EHR-013", "escalate_care",
        lambda i: {"patient_id": "EHR-013", "team": "gastroenterology", "reason": f"re-bleed episode {i}: endoscopy"}))
    big = max(syn, key=lambda t: len(m.store().raw(t.patient_id))).patient_id
    out["READ get_lab_trend"] = _ms(calls("EHR-010", "get_lab_trend",
                                          lambda i: {"patient_id": "EHR-010", "test": "potassium"}))
    out["READ calculate_sofa"] = _ms(calls("EHR-001", "calculate_sofa", lambda i: {"patient_id": "EHR-001"}))
    out[f"READ get_condition_history ({big})"] = _ms(calls(big, "get_condition_history", lambda i: {"patient_id": big}))
    out[f"READ get_medications_on_date ({big})"] = _ms(calls(
        big, "get_medications_on_date", lambda i: {"patient_id": big, "date": "2010-06-01"}))
    for key, value in out.items():
        print(f"{key:55s} {value}")
    return out


if __name__ == "__main__":
    main()
