"""Evaluation suites: config files naming benchmarks, and their resolution to tasks the user has.

A suite is a YAML file in `evals/suites/` (or any path) validated by `SuiteSpec`:

    name: paper18
    description: ...
    benchmarks:
      - name: medqa                    # what results rows carry in `benchmark`
        title: MedQA (USMLE)           # how reports print it
        category: MC QA                # report grouping (the paper's categories)
        metric: accuracy               # accuracy | vqa_accuracy | action_coverage | long_form | gym (evals.metrics)
        paper_samples: 1273            # the paper's count (Appendix "Benchmark Suite"), for the missing report
        select:                        # which tasks count for it
          domain: medical_qa
          split: imported              # tasks brought by `hcgym tasks import` (default); or train/test/validation
          formats: [medqa]             # the converter that produced them (task.description.source)
          metadata: {subject: [anatomy]}   # optional: task.metadata[key] starts with one of these (normalised)
          limit: null                  # optional: a seeded sample of at most this many tasks
          seed: 0
        import: ["hcgym tasks import --format medqa PATH/test.jsonl"]   # how to bring it when missing

`resolve(name)` returns a `ResolvedSuite`: per benchmark the `EvalItem`s found, and for each
benchmark with none the reason and the exact import command(s). A name that is not a suite file
but a benchmark of one (e.g. `medqa`) resolves to a one-benchmark suite.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from evals.types import EvalItem

SUITES_DIR = Path(__file__).resolve().parent / "suites"
# Suites searched (in this order) for a single benchmark name such as `medqa`.
CATALOGUE_ORDER = ("paper18", "gym-heldout", "gym-validation")

MetricName = Literal["accuracy", "vqa_accuracy", "action_coverage", "long_form", "gym"]


class TaskSelection(BaseModel):
    model_config = ConfigDict(extra="forbid")
    domain: str
    split: str = "imported"
    formats: list[str] = Field(default_factory=list)
    metadata: dict[str, list[str]] = Field(default_factory=dict)
    task_id_pattern: str | None = Field(default=None, description="keep task ids this regex finds (re.search)")
    limit: int | None = Field(default=None, ge=1)

    @field_validator("task_id_pattern")
    @classmethod
    def _compiles(cls, value: str | None) -> str | None:
        if value is not None:
            try:
                re.compile(value)
            except re.error as exc:
                raise ValueError(f"task_id_pattern {value!r} is not a regular expression: {exc}") from exc
        return value
    seed: int = 0


class BenchmarkSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    name: str = Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$")
    title: str
    category: str
    metric: MetricName
    select: TaskSelection
    paper_samples: int | None = None
    import_commands: list[str] = Field(default_factory=list, alias="import")


#: `select.domain` of a benchmark that stands for every registered domain.
EVERY_DOMAIN = "*"


class SuiteSpec(BaseModel):
    """A suite file. A benchmark whose `select.domain` is "*" stands for one benchmark per registered
    domain (`envs.registry`), its `name` and `title` formatted with `{domain}`: a new domain joins the
    gym suites without an edit."""

    model_config = ConfigDict(extra="forbid")
    name: str
    description: str = ""
    benchmarks: list[BenchmarkSpec] = Field(min_length=1)

    @model_validator(mode="before")
    @classmethod
    def _every_domain(cls, data: Any) -> Any:
        if not isinstance(data, dict) or not isinstance(data.get("benchmarks"), list):
            return data
        expanded: list[Any] = []
        for bench in data["benchmarks"]:
            select = bench.get("select") if isinstance(bench, dict) else None
            if not (isinstance(select, dict) and select.get("domain") == EVERY_DOMAIN):
                expanded.append(bench)
                continue
            from envs import registry

            for domain in registry.list_domains():
                expanded.append({**bench, "name": str(bench.get("name", "")).format(domain=domain),
                                 "title": str(bench.get("title", "")).format(domain=domain),
                                 "select": {**select, "domain": domain}})
        return {**data, "benchmarks": expanded}

    @model_validator(mode="after")
    def _unique_names(self) -> SuiteSpec:
        names = [b.name for b in self.benchmarks]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"benchmark names must be unique within a suite; repeated: {duplicates}")
        return self


class ResolvedBenchmark(BaseModel):
    spec: BenchmarkSpec
    items: list[EvalItem]


class MissingBenchmark(BaseModel):
    name: str
    title: str
    reason: str
    commands: list[str]


class ResolvedSuite(BaseModel):
    name: str
    description: str = ""
    benchmarks: list[ResolvedBenchmark]
    missing: list[MissingBenchmark]

    @property
    def items(self) -> list[EvalItem]:
        return [item for bench in self.benchmarks for item in bench.items]

    def spec(self, benchmark: str) -> BenchmarkSpec:
        for bench in self.benchmarks:
            if bench.spec.name == benchmark:
                return bench.spec
        raise KeyError(f"suite {self.name!r} has no resolved benchmark {benchmark!r}")

    def missing_report(self) -> str:
        """Markdown: which benchmarks have no tasks yet, and the command(s) that bring each."""
        if not self.missing:
            return f"All {len(self.benchmarks)} benchmarks of suite `{self.name}` resolved.\n"
        total = len(self.missing) + len(self.benchmarks)
        lines = [f"{len(self.missing)} of {total} benchmarks of suite `{self.name}` have no tasks yet (they are skipped):",
                 ""]
        for miss in self.missing:
            lines.append(f"- **{miss.title}** (`{miss.name}`): {miss.reason}")
            lines.extend(f"    `{command}`" for command in miss.commands)
        return "\n".join(lines) + "\n"


class SuiteError(ValueError):
    """A suite name or file that cannot be used (unknown, unreadable, invalid)."""


def available_suites() -> list[str]:
    return sorted(p.stem for p in SUITES_DIR.glob("*.yaml"))


def load_suite_file(path: Path) -> SuiteSpec:
    if not path.is_file():
        raise SuiteError(f"{path}: suite file not found")
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise SuiteError(f"{path}: not valid YAML: {exc}") from None
    try:
        return SuiteSpec.model_validate(raw)
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'suite'}: {e['msg']}" for e in exc.errors())
        raise SuiteError(f"{path}: {problems}") from None


def load_suite(name: str) -> SuiteSpec:
    """A suite by file path, by name in `evals/suites/`, or a single benchmark of a known suite."""
    candidate = Path(name)
    if candidate.suffix in (".yaml", ".yml"):
        return load_suite_file(candidate)
    if (SUITES_DIR / f"{name}.yaml").is_file():
        return load_suite_file(SUITES_DIR / f"{name}.yaml")
    known: list[str] = []
    ordered = [s for s in CATALOGUE_ORDER if s in available_suites()]
    for suite_name in ordered + [s for s in available_suites() if s not in ordered]:
        suite = load_suite_file(SUITES_DIR / f"{suite_name}.yaml")
        for bench in suite.benchmarks:
            if bench.name == name:
                return SuiteSpec(name=name, description=f"{bench.title} (from suite {suite.name})", benchmarks=[bench])
            known.append(bench.name)
    raise SuiteError(f"unknown suite or benchmark {name!r}; suites: {', '.join(available_suites())}; "
                     f"benchmarks: {', '.join(sorted(set(known)))}")


def _normalise(value: object) -> str:
    return re.sub(r"[^a-z0-9]", "", str(value).lower())


def _matches(task, selection: TaskSelection) -> bool:
    if selection.formats and (task.description.source or "") not in selection.formats:
        return False
    if selection.task_id_pattern is not None and not re.search(selection.task_id_pattern, task.id):
        return False
    for key, wanted in selection.metadata.items():
        value = _normalise(task.metadata.get(key, ""))
        if not value or not any(value.startswith(_normalise(w)) for w in wanted):
            return False
    return True


def _domain_tasks(domain: str, split: str):
    """Tasks of one split. Imported tasks are read from their folder directly (cheaper than building
    the domain's whole store, and it works before `hcgym data build` has run)."""
    from envs import registry
    from envs.core.domain import imported_tasks_dir
    from envs.core.task import load_tasks

    if domain not in registry.list_domains():
        raise SuiteError(f"unknown domain {domain!r}; domains: {', '.join(registry.list_domains())}")
    if split == "imported":
        folder = imported_tasks_dir(domain)
        files = sorted(folder.glob("*.json")) if folder.is_dir() else []
        return [task for path in files for task in load_tasks(path, domain=domain)]
    return registry.get_tasks(domain, split=split)


def _sample(task_ids: list[str], limit: int | None, seed: int) -> list[str]:
    """A deterministic subset: the same (ids, limit, seed) always gives the same tasks, in id order."""
    ordered = sorted(task_ids)
    if limit is None or limit >= len(ordered):
        return ordered
    chosen = np.random.default_rng(seed).choice(len(ordered), size=limit, replace=False)
    return [ordered[i] for i in sorted(chosen)]


def import_commands(spec: BenchmarkSpec) -> list[str]:
    """The spec's import commands with `{imported}` replaced by the domain's imported-task folder."""
    from envs.core.domain import imported_tasks_dir

    folder = str(imported_tasks_dir(spec.select.domain))
    return [command.replace("{imported}", folder) for command in spec.import_commands]


def resolve_spec(suite: SuiteSpec) -> ResolvedSuite:
    resolved: list[ResolvedBenchmark] = []
    missing: list[MissingBenchmark] = []
    cache: dict[tuple[str, str], list] = {}
    for spec in suite.benchmarks:
        sel = spec.select
        key = (sel.domain, sel.split)
        try:
            if key not in cache:
                cache[key] = _domain_tasks(sel.domain, sel.split)
        except KeyError as exc:  # the domain has no such split
            missing.append(MissingBenchmark(name=spec.name, title=spec.title, reason=str(exc).strip("'\""),
                                            commands=import_commands(spec)))
            continue
        ids = [t.id for t in cache[key] if _matches(t, sel)]
        if not ids:
            where = f"domain {sel.domain!r} split {sel.split!r}"
            what = f"formats {sel.formats}" if sel.formats else "any task"
            if sel.metadata:
                what += f" with metadata {sel.metadata}"
            if sel.task_id_pattern:
                what += f" with an id matching {sel.task_id_pattern!r}"
            reason = f"no {what} in {where}" + (f" (the paper uses {spec.paper_samples})" if spec.paper_samples else "")
            missing.append(MissingBenchmark(name=spec.name, title=spec.title, reason=reason,
                                            commands=import_commands(spec)))
            continue
        items = [EvalItem(benchmark=spec.name, domain=sel.domain, task_id=task_id, split=sel.split)
                 for task_id in _sample(ids, sel.limit, sel.seed)]
        resolved.append(ResolvedBenchmark(spec=spec, items=items))
    return ResolvedSuite(name=suite.name, description=suite.description, benchmarks=resolved, missing=missing)


def resolve(suite_name: str) -> ResolvedSuite:
    """Map each benchmark of a suite (name, path, or single benchmark) to the tasks available here."""
    return resolve_spec(load_suite(suite_name))


def benchmark_specs(suite_name: str | None) -> dict[str, BenchmarkSpec]:
    """Benchmark name -> spec for a suite, without resolving tasks (reports use it for metrics and titles).
    Unknown suites give an empty map: reports then fall back to plain accuracy."""
    if not suite_name:
        return {}
    try:
        return {b.name: b for b in load_suite(suite_name).benchmarks}
    except SuiteError:
        return {}


__all__ = [
    "SUITES_DIR",
    "BenchmarkSpec",
    "MissingBenchmark",
    "ResolvedBenchmark",
    "ResolvedSuite",
    "SuiteError",
    "SuiteSpec",
    "TaskSelection",
    "available_suites",
    "benchmark_specs",
    "import_commands",
    "load_suite",
    "load_suite_file",
    "resolve",
    "resolve_spec",
]
