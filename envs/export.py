"""`hcgym tasks export`: the gym's tasks as a dataset (Parquet or JSONL) for other trainers.

One row per task: what a trainer needs to start the task's episode and render its first prompt
(`prompt` in the chat-message form TRL and `datasets` read, built from `HealthcareGymEnv.prompt()`),
the task's tool schemas, and its answer metadata in a column of its own, never in the prompt. The
rows are read back with `datasets.load_dataset("parquet" | "json", data_files=...)`; TRL's
`environment_factory` (`envs.integrations.trl`) passes each row to `reset(**row)`, which starts the
row's task by its `task_id`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict

ExportFormat = Literal["parquet", "jsonl"]
FORMATS: tuple[str, ...] = ("parquet", "jsonl")


class TaskRow(BaseModel):
    """One exported task.

    Attributes:
        task_id: The task's id (`HealthcareGymEnv.reset(options={"task_id": ...})`).
        domain: The task's domain.
        split: The split it belongs to.
        prompt: The first chat messages (system: the domain policy; user: the ticket), without the
            env's tool block: a trainer renders `tools` with its own chat template.
        tools: The task's tool schemas (OpenAI function format) as JSON text, in the env's order.
        image_path: The task's image for a vision task, else None.
        answer: The grading metadata as JSON text (`answer_type`, `correct_answer`, aliases,
            tolerance, unit, options): for reward code and analysis; never shown to the policy.
    """

    model_config = ConfigDict(extra="forbid")
    task_id: str
    domain: str
    split: str
    prompt: list[dict[str, str]]
    tools: str
    image_path: str | None = None
    answer: str


def task_rows(domain: str, split: str | None = None) -> list[TaskRow]:
    """The rows of one domain's tasks (every split when `split` is None), in the registry's order.

    Raises:
        ValueError: An unknown domain or a split the domain does not have.
    """
    from envs import registry
    from envs.env import HealthcareGymEnv

    if domain not in registry.list_domains():
        raise ValueError(f"--domain {domain!r}: unknown domain; one of {', '.join(registry.list_domains())}")
    splits = registry.get_splits(domain)
    if split is not None and split not in splits:
        raise ValueError(f"--split {split!r}: domain {domain!r} has splits {', '.join(sorted(splits))}")
    rows: list[TaskRow] = []
    for name in ([split] if split is not None else list(splits)):
        if not registry.get_tasks(domain, name):
            continue
        env = HealthcareGymEnv(domain=domain, split=name)
        for task in env.tasks:
            env.reset(options={"task_id": task.id})
            parts = env.prompt()
            # The text content of the ticket only: the image travels in `image_path` (one column type
            # for every row, which Parquet needs).
            prompt = [{"role": "system", "content": parts.system}, {"role": "user", "content": parts.ticket}]
            answer = {"answer_type": task.answer_type, "correct_answer": task.correct_answer,
                      "answer_aliases": task.answer_aliases, "answer_tolerance": task.answer_tolerance,
                      "answer_unit": task.answer_unit, "options": task.options}
            rows.append(TaskRow(task_id=task.id, domain=domain, split=name, prompt=prompt,
                                tools=json.dumps(parts.tools, ensure_ascii=False), image_path=parts.image_path,
                                answer=json.dumps(answer, ensure_ascii=False)))
    return rows


def export_tasks(out_dir: str | Path, *, domains: list[str], split: str | None = None,
                 fmt: ExportFormat = "parquet") -> dict[str, Any]:
    """Write one file per domain, `<out_dir>/<domain>.<parquet|jsonl>`.

    Returns:
        {domain: {"path": file written, "rows": row count}}; a domain with no task in `split` is
        left out (no empty file).

    Raises:
        ValueError: An unknown format, domain or split.
    """
    if fmt not in FORMATS:
        raise ValueError(f"--format {fmt!r}: expected one of {', '.join(FORMATS)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Any] = {}
    for domain in domains:
        rows = [row.model_dump() for row in task_rows(domain, split)]
        if not rows:
            continue
        path = out / f"{domain}.{fmt}"
        tmp = path.with_name(path.name + ".tmp")
        if fmt == "jsonl":
            with tmp.open("w", encoding="utf-8") as f:
                for row in rows:
                    f.write(json.dumps(row, ensure_ascii=False) + "\n")
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            pq.write_table(pa.Table.from_pylist(rows), tmp)
        tmp.replace(path)
        written[domain] = {"path": str(path), "rows": len(rows)}
    return written
