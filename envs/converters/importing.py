"""`hcgym tasks import`: convert, check, and write imported tasks without losing or overwriting anything.

One import job = one source file (or MIMIC/eICU folder) -> one task file in the domain's imported-task
folder (`<data>/imported/<domain>/<format>-<source name>.json`, loaded with the domain as split
`imported`). For each job:
1. convert (a benchmark converter, or the reference importer); rows that cannot be read are reported
   with file and line;
2. check every task statically (`envs.validate.static_problems`): tasks naming tools the domain lacks
   are never imported; ungradeable ones (no gold answer, nothing to grade, required arguments missing or
   empty, arguments that do not fit) are reported by reason and left out unless `keep_ungradeable`;
3. drop ids already used in the domain (its own tasks or another import) or repeated in the file,
   reporting each (one duplicate id would otherwise stop the whole domain from loading);
4. write only if something is left, and never over an existing file unless `replace`.
The per-domain table (read / imported / rejected by reason) and the first `show_errors` problems are
printed; the exit status is 1 when any job wrote nothing.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from envs.core.task import Task

VQA_FORMATS = ("vqa-rad", "slake", "pathvqa", "pmc-vqa", "vqa-med-2021", "quilt-vqa")
EHR_FORMATS = ("mimic3", "eicu")
ROW_ERROR = "unreadable row"
DUPLICATE = "duplicate id"


@dataclass
class ImportJob:
    domain: str
    source: Path
    output: Path
    read: int = 0
    written: int = 0
    rejected: Counter = field(default_factory=Counter)
    kept_ungradeable: Counter = field(default_factory=Counter)
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    failed: str | None = None  # why nothing was written


def default_domain(fmt: str) -> str:
    return "visual_diagnosis" if fmt in VQA_FORMATS else "ehr_management" if fmt in EHR_FORMATS else "medical_qa"


def source_stem(path: Path) -> str:
    """`mmlu/anatomy_test.csv` -> `anatomy_test`, `x.jsonl.gz` -> `x`, a MIMIC folder -> its name."""
    name = path.resolve().name
    for suffix in (".gz", ".csv", ".jsonl", ".json", ".txt", ".parquet", ".pkl", ".pickle"):
        name = name.removesuffix(suffix)
    return name or "source"


def reference_sources(path: Path, domain: str | None) -> list[tuple[str, Path]]:
    """(domain, task file) pairs: one file (its domain from --domain or its folder's name), or a folder laid
    out like the reference's `data/domains/` (`<domain>/tasks*.json`) or one domain folder of it."""
    from envs import registry

    if path.is_file():
        chosen = domain or (path.parent.name if path.parent.name in registry.DOMAINS else None)
        if chosen is None:
            raise ValueError(f"{path}: pass --domain (the file's folder {path.parent.name!r} is not a domain name)")
        return [(chosen, path)]
    if not path.is_dir():
        raise ValueError(f"{path}: file or folder not found")
    if path.name in registry.DOMAINS or domain:
        files = sorted(path.glob("tasks*.json"))
        return [(domain or path.name, f) for f in files]
    if domain:
        raise ValueError("--domain applies to one task file or one domain folder, not to a folder of domains")
    pairs = [(sub.name, f) for sub in sorted(path.iterdir()) if sub.is_dir() and sub.name in registry.DOMAINS
             for f in sorted(sub.glob("tasks*.json"))]
    for sub in sorted(path.iterdir()):
        if sub.is_dir() and sub.name not in registry.DOMAINS and any(sub.glob("tasks*.json")):
            print(f"note: {sub}: skipped, {sub.name!r} is not a domain here (import it with --domain NAME)")
    if not pairs:
        raise ValueError(f"{path}: no <domain>/tasks*.json files (domains: {', '.join(registry.DOMAINS)})")
    return pairs


def existing_ids(domain: str, output: Path) -> dict[str, str]:
    """id -> where it is already defined in the domain: its own (authored or built) tasks and every other
    imported file. The file being written is excluded (with --replace it is rewritten)."""
    from envs.core.domain import imported_tasks_dir

    found: dict[str, str] = {}
    folder = imported_tasks_dir(domain)
    imported_files = sorted(folder.glob("*.json")) if folder.is_dir() else []
    for other in imported_files:
        if other.resolve() == output.resolve():
            continue
        try:
            items = json.loads(other.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ValueError(f"{other}: cannot read an already imported task file to check ids: {exc}") from None
        for item in items if isinstance(items, list) else []:
            if isinstance(item, dict) and isinstance(item.get("id"), str):
                found.setdefault(item["id"], str(other))
    imported_ids = set(found)
    if output.is_file():
        try:
            imported_ids |= {i.get("id") for i in json.loads(output.read_text(encoding="utf-8")) if isinstance(i, dict)}
        except (OSError, ValueError, TypeError, AttributeError):
            pass
    for task_id, where in _own_task_ids(domain).items():
        if task_id not in imported_ids:
            found.setdefault(task_id, where)
    return found


def _own_task_ids(domain: str) -> dict[str, str]:
    """The ids of the domain's own tasks (authored in its folder, generated by the data build), read from the
    files rather than the domain's cached store, which may hold tasks of another data folder."""
    from envs import registry
    from envs.core.db import DataFileError
    from envs.core.paths import domain_build_dir
    from envs.core.task import load_tasks

    module = registry.domain_module(domain)
    files = [Path(module.__file__).parent / "tasks.json", domain_build_dir(domain) / "tasks.json"]
    ids: dict[str, str] = {}
    for path in files:
        if path.is_file():
            try:
                ids.update({t.id: str(path) for t in load_tasks(path, domain=domain)})
            except DataFileError:
                continue  # the domain's own file problem is reported when the domain loads
    if not any(path.is_file() for path in files) and hasattr(module, "get_tasks"):
        # a domain whose tasks are made in code (cross_domain's pathways); a domain not built yet has none
        try:
            ids.update({t.id: f"the {domain!r} domain's tasks" for t in module.get_tasks()})
        except (DataFileError, KeyError, ValueError):
            pass
    return ids


def _definitions(domain: str):
    from envs import registry

    definitions = registry.get_environment(domain).toolkit.definitions
    per_task = getattr(registry.domain_module(domain), "task_tool_definitions", None)
    return definitions, per_task


def screen(job: ImportJob, tasks: list[Task], *, keep_ungradeable: bool) -> list[Task]:
    """Static validation of every task (step 2 of the module docstring)."""
    from envs.validate import UNKNOWN_TOOL, static_problems

    loaded: list[Any] = []  # the domain's tools, loaded on the first task with expected actions
    kept = []
    for task in tasks:
        defs: dict = {}
        if task.evaluation_criteria.actions:
            if not loaded:
                loaded.extend(_definitions(job.domain))
            definitions, per_task = loaded
            try:
                defs = per_task(task) if per_task else definitions
            except (KeyError, ValueError):
                defs = definitions
        problems = static_problems(task, job.domain, defs)
        if not problems:
            kept.append(task)
            continue
        reasons = sorted({reason for reason, _ in problems})
        detail = "; ".join(message for _, message in problems)
        if UNKNOWN_TOOL in reasons or not keep_ungradeable:
            job.rejected[reasons[0] if UNKNOWN_TOOL not in reasons else UNKNOWN_TOOL] += 1
            job.problems.append(f"task {task.id}: not imported ({', '.join(reasons)}): {detail}")
        else:
            job.kept_ungradeable[reasons[0]] += 1
            job.problems.append(f"task {task.id}: imported though ungradeable (--keep-ungradeable): {detail}")
            kept.append(task)
    return kept


def replay_gold(job: ImportJob, tasks: list[Task], *, keep_ungradeable: bool) -> list[Task]:
    """`--replay`: run each task's gold solution in a fresh episode (`envs.validate.validate_task`):
    expected actions that fail (e.g. a patient the domain does not have) or a gold answer the grader does
    not give full marks are reported as `gold replay fails`."""
    from envs.validate import REPLAY_FAILS, validate_task

    definitions, per_task = _definitions(job.domain)
    kept = []
    for task in tasks:
        try:
            defs = per_task(task) if per_task else definitions
        except (KeyError, ValueError):
            defs = definitions
        report = validate_task(task, job.domain, defs, replay=True)
        if report.ok:
            kept.append(task)
        elif keep_ungradeable:
            job.kept_ungradeable[REPLAY_FAILS] += 1
            job.problems.append(f"task {task.id}: imported though its gold replay fails: {'; '.join(report.problems)}")
            kept.append(task)
        else:
            job.rejected[REPLAY_FAILS] += 1
            job.problems.append(f"task {task.id}: not imported ({REPLAY_FAILS}): {'; '.join(report.problems)}")
    return kept


def finish(job: ImportJob, tasks: list[Task], *, replace: bool, keep_ungradeable: bool, replay: bool = False) -> None:
    from envs.core.domain import imported_tasks_dir
    from envs.core.task import dump_tasks

    tasks = screen(job, tasks, keep_ungradeable=keep_ungradeable)
    if replay:
        tasks = replay_gold(job, tasks, keep_ungradeable=keep_ungradeable)
    inside = job.output.resolve().parent == imported_tasks_dir(job.domain).resolve()
    existing = existing_ids(job.domain, job.output) if inside else {}
    seen: set[str] = set()
    kept = []
    for task in tasks:
        if task.id in existing:
            job.rejected[DUPLICATE] += 1
            job.problems.append(f"id {task.id} already defined in {existing[task.id]}: not imported again")
        elif task.id in seen:
            job.rejected[DUPLICATE] += 1
            job.problems.append(f"id {task.id} occurs more than once in {job.source}: kept the first")
        else:
            seen.add(task.id)
            kept.append(task)
    if not kept:
        job.failed = f"{job.source}: no task could be imported; nothing was written to {job.output}"
        return
    if job.output.exists() and not replace:  # checked again: another import may have written it meanwhile
        job.failed = _exists_message(job.output)
        return
    dump_tasks(kept, job.output)
    job.written = len(kept)


def _exists_message(output: Path) -> str:
    try:
        count = len(json.loads(output.read_text(encoding="utf-8")))
        holds = f"holds {count} tasks"
    except (OSError, ValueError, TypeError):
        holds = "exists"
    return f"{output} {holds}: not replaced (pass --replace to replace it)"


def run_import(args: Any) -> int:
    """The `hcgym tasks import` command (see the module docstring)."""
    from envs.converters.formats import cyclic_gc_paused

    path = Path(args.path)
    if args.format == "reference":
        sources = reference_sources(path, args.domain)
        if args.output and len(sources) > 1:
            raise ValueError("--output names one file; a folder of reference task files writes one per source")
    else:
        sources = [(args.domain or default_domain(args.format), path)]
    jobs: list[ImportJob] = []
    with cyclic_gc_paused():  # the whole job holds every task (convert, check, write): see the helper
        _run_jobs(args, sources, jobs)
    report(jobs, show_errors=args.show_errors)
    return 1 if any(job.failed for job in jobs) else 0


def _run_jobs(args: Any, sources: list[tuple[str, Path]], jobs: list[ImportJob]) -> None:
    from envs.core.domain import imported_tasks_dir

    for domain, source in sources:
        output = Path(args.output) if args.output else \
            imported_tasks_dir(domain) / f"{args.format}-{source_stem(source)}.json"
        job = ImportJob(domain=domain, source=source, output=output)
        jobs.append(job)
        if output.exists() and not args.replace:
            job.failed = _exists_message(output)  # refused before converting anything
            continue
        try:
            tasks = _convert(args, job)
        except ValueError as exc:  # the whole file cannot be read (SourceFileError, DataFileError): name it, go on
            if len(sources) == 1:
                raise
            job.failed = str(exc)
            continue
        finish(job, tasks, replace=args.replace, keep_ungradeable=args.keep_ungradeable,
               replay=getattr(args, "replay", False))


def _convert(args: Any, job: ImportJob) -> list[Task]:
    if args.format == "reference":
        from envs.converters.reference import import_reference_tasks

        result = import_reference_tasks(job.source, domain=job.domain)
        job.read, job.notes = result.rows_read, list(result.notes)
        job.rejected.update(result.rejected)
        job.problems.extend(result.issues)
        return result.tasks
    from envs.converters import convert

    converted = convert(args.format, job.source, domain=job.domain, image_dir=args.image_dir,
                        cop_base=args.cop_base, max_stays=args.max_stays)
    job.read, job.notes = converted.rows_read, list(converted.notes)
    if converted.errors:
        job.rejected[ROW_ERROR] += len(converted.errors)
        job.problems.extend(str(e) for e in converted.errors)
    return converted.tasks


def report(jobs: list[ImportJob], *, show_errors: int) -> None:
    for job in jobs:
        for note in job.notes:
            print(f"note: {note}")
    by_domain: dict[str, list[ImportJob]] = {}
    for job in jobs:
        by_domain.setdefault(job.domain, []).append(job)
    print(f"{'domain':20s} {'read':>7s} {'imported':>9s} {'rejected':>9s}  rejected by reason")
    for domain, group in by_domain.items():
        reasons: Counter = Counter()
        for job in group:
            reasons.update(job.rejected)
        kept_bad: Counter = Counter()
        for job in group:
            kept_bad.update(job.kept_ungradeable)
        why = ", ".join(f"{reason} {count}" for reason, count in reasons.most_common()) or "-"
        if kept_bad:
            why += "; kept though ungradeable: " + ", ".join(f"{r} {c}" for r, c in kept_bad.most_common())
        print(f"{domain:20s} {sum(j.read for j in group):7d} {sum(j.written for j in group):9d} "
              f"{sum(reasons.values()):9d}  {why}")
    for job in jobs:
        if job.written:
            print(f"imported {job.written} tasks into {job.output}; {sum(job.rejected.values())} rejected")
        stream = sys.stderr if job.failed else sys.stdout
        if job.failed:
            print(f"error: {job.failed}", file=sys.stderr)
        if job.problems:
            shown = job.problems[:show_errors] if show_errors >= 0 else job.problems
            print(f"{len(job.problems)} problem(s) in {job.source}" + (
                f" (first {len(shown)}; --show-errors N for more)" if len(shown) < len(job.problems) else "") + ":",
                file=stream)
            for line in shown:
                print(f"  {line}", file=stream)
