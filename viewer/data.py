"""What the viewer reads: training runs and evaluation folders, as the project writes them.

No second format: a run folder is what `hcgym train` writes (`metrics.jsonl`, `config.yaml`,
`trajectories/step_*.parquet`, `validation/step_*.parquet`), an evaluation folder what `hcgym eval`
writes (`eval.json`, `results.parquet`, `trajectories.parquet`). Nothing is written back.

Speed on real sizes comes from reading only what a page needs: the episode table is an in-memory
Arrow table of the scalar columns (projected reads; the token and JSON columns stay on disk),
filtered with Arrow compute kernels and paged; one episode's full record is read from the row group
of its own file that holds it, and decoded row groups are kept in a least-recently-used cache bounded
in bytes, so a flood of episode requests costs one decode per row group, not one per request.
"""

from __future__ import annotations

import json
import math
import threading
from abc import ABC, abstractmethod
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

#: Scalar columns of a training episode that the table shows and filters on (learner/metrics.py).
RUN_INDEX_COLUMNS = ("sample_id", "task_id", "domain", "step", "reward", "correct", "truncated", "num_tool_calls",
                     "response_tokens", "accepted", "teacher_hint", "end_reason", "safety_max_severity",
                     "error_kinds")
RUN_INDEX_TYPES = {"sample_id": pa.string(), "task_id": pa.string(), "domain": pa.string(), "step": pa.int32(),
                   "reward": pa.float64(), "correct": pa.bool_(), "truncated": pa.bool_(),
                   "num_tool_calls": pa.int32(), "response_tokens": pa.int32(), "accepted": pa.bool_(),
                   "teacher_hint": pa.string(), "end_reason": pa.string(), "safety_max_severity": pa.int8(),
                   "error_kinds": pa.list_(pa.string())}
MAX_PAGE = 500
#: Accepted range of each integer filter: the column's own type bounds it (step int32, severity int8),
#: so a 23-digit value is a bad request named as such, not an overflow inside Arrow.
INT_RANGES = {"step": (0, 2**31 - 1), "min_severity": (0, 127), "offset": (0, 2**31 - 1), "limit": (1, MAX_PAGE)}
#: Decoded trajectory row groups kept for episode pages (bytes of Arrow buffers).
EPISODE_CACHE_BYTES = 256 * 2**20
#: Columns an episode page never shows nor needs (per_turn_kl uses the masks and log-probs only).
_EPISODE_SKIP = ("policy_versions", "input_ids")


class ViewerError(ValueError):
    """A request the viewer cannot answer (unknown source, bad filter value); the message says why."""


@dataclass
class EpisodeQuery:
    """Filters of the episode table; None means "any"."""

    part: str | None = None            # "train" / "validation" for runs
    step: int | None = None
    domain: str | None = None
    task: str | None = None            # substring of the task id
    reward_min: float | None = None
    reward_max: float | None = None
    correct: bool | None = None
    min_severity: int | None = None    # worst safety violation >= this (1-5)
    error_kind: str | None = None
    end_reason: str | None = None
    benchmark: str | None = None       # evaluations
    offset: int = 0
    limit: int = 50

    @classmethod
    def from_params(cls, params: dict[str, str]) -> EpisodeQuery:
        """Parse URL query parameters; a bad value raises ViewerError naming the parameter."""
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(params) - known - {"source"})
        if unknown:
            raise ViewerError(f"unknown filter parameter(s) {unknown}; known: {sorted(known)}")
        out = cls()
        for name, raw in params.items():
            if name == "source" or raw == "":
                continue
            kind = cls.__dataclass_fields__[name].type
            try:
                if "int" in str(kind):
                    value: Any = int(raw)
                elif "float" in str(kind):
                    value = float(raw)
                    if not math.isfinite(value):
                        raise ValueError("not finite")
                elif "bool" in str(kind):
                    if raw not in ("true", "false"):
                        raise ValueError("expected true or false")
                    value = raw == "true"
                else:
                    value = raw
            except ValueError as exc:
                raise ViewerError(f"filter {name}={_short(raw)}: {exc}") from None
            if name in INT_RANGES and not INT_RANGES[name][0] <= value <= INT_RANGES[name][1]:
                low, high = INT_RANGES[name]
                raise ViewerError(f"filter {name}={_short(raw)}: expected an integer in [{low}, {high}]")
            setattr(out, name, value)
        return out


def _short(raw: str, limit: int = 40) -> str:
    """A request value quoted for an error message, cut so a huge value does not come back whole."""
    return repr(raw) if len(raw) <= limit else f"{raw[:limit]!r}... ({len(raw)} characters)"


class RowGroupCache:
    """Decoded row groups of trajectory files, least recently used first out, at most `max_bytes`.

    Keyed by path, size and modification time, so a rewritten file is read again. One lock per row
    group: concurrent requests for episodes of one step decode it once and share the table.
    """

    def __init__(self, max_bytes: int = EPISODE_CACHE_BYTES) -> None:
        self.max_bytes = max_bytes
        self._tables: OrderedDict[tuple, pa.Table] = OrderedDict()
        self._layouts: OrderedDict[tuple, tuple[list[int], list[str]]] = OrderedDict()
        self._locks: dict[tuple, threading.Lock] = {}
        self._lock = threading.Lock()
        self.reads = 0  # row groups decoded (a figure for tests and benchmarks)

    def nbytes(self) -> int:
        with self._lock:
            return sum(t.nbytes for t in self._tables.values())

    def row(self, path: Path, row: int) -> tuple[pa.Table, int, int]:
        """(the decoded row group holding `row`, the row's index in it, the file's row count)."""
        stat = path.stat()
        key = (str(path), stat.st_size, stat.st_mtime_ns)
        with self._lock:
            layout = self._layouts.get(key)
            if layout is not None:
                self._layouts.move_to_end(key)
        if layout is None:
            meta = pq.ParquetFile(path).metadata
            starts = [0]
            for i in range(meta.num_row_groups):
                starts.append(starts[-1] + meta.row_group(i).num_rows)
            columns = [c for c in meta.schema.to_arrow_schema().names if c not in _EPISODE_SKIP]
            layout = (starts, columns)
            with self._lock:
                self._layouts[key] = layout
                while len(self._layouts) > 4096:
                    self._layouts.popitem(last=False)
        starts, columns = layout
        total = starts[-1]
        if not 0 <= row < total:
            return pa.table({}), -1, total
        group = next(i for i in range(len(starts) - 1) if starts[i] <= row < starts[i + 1])
        group_key = (*key, group)
        with self._lock:
            table = self._tables.get(group_key)
            if table is not None:
                self._tables.move_to_end(group_key)
                return table, row - starts[group], total
            group_lock = self._locks.setdefault(group_key, threading.Lock())
        with group_lock:
            with self._lock:
                table = self._tables.get(group_key)
            if table is None:
                table = pq.ParquetFile(path).read_row_group(group, columns=columns)
                with self._lock:
                    self.reads += 1
                    if table.nbytes <= self.max_bytes:
                        self._tables[group_key] = table
                        used = sum(t.nbytes for t in self._tables.values())
                        while used > self.max_bytes:
                            _, dropped = self._tables.popitem(last=False)
                            used -= dropped.nbytes
            with self._lock:
                self._locks.pop(group_key, None)
        return table, row - starts[group], total


EPISODE_CACHE = RowGroupCache()


def _read_projected(path: Path, columns: tuple[str, ...], types: dict[str, pa.DataType]) -> pa.Table:
    """The named columns of one Parquet file; columns an older file lacks come back as nulls."""
    present = set(pq.read_schema(path).names)
    table = pq.read_table(path, columns=[c for c in columns if c in present])
    n = table.num_rows
    arrays = [table.column(c).cast(types[c]) if c in present else pa.nulls(n, types[c]) for c in columns]
    return pa.table(dict(zip(columns, arrays)))


def _current_end_reasons(table: pa.Table) -> pa.Table:
    """Episodes written before the one end-reason vocabulary (`envs.episode.EndReason`) named a cut by
    training's truncation label ("max_turns", "response_tokens"): shown under the current names, so
    the column (and its filter) holds one vocabulary across old and new files."""
    from envs.episode import LEGACY_END_REASONS

    column = table.column("end_reason")
    if not pc.any(pc.is_in(column, value_set=pa.array(list(LEGACY_END_REASONS), pa.string()))).as_py():
        return table
    mapped = [None if v is None else LEGACY_END_REASONS.get(v, v) for v in column.to_pylist()]
    return table.set_column(table.schema.get_field_index("end_reason"), "end_reason", pa.array(mapped, pa.string()))


def _mask_for(table: pa.Table, query: EpisodeQuery) -> pa.ChunkedArray | None:
    conditions = []
    names = set(table.column_names)

    def eq(column: str, value: Any) -> None:
        if column in names:
            conditions.append(pc.equal(table[column], pa.scalar(value, table[column].type)))

    if query.part is not None:
        eq("part", query.part)
    if query.step is not None:
        eq("step", query.step)
    if query.domain is not None:
        eq("domain", query.domain)
    if query.benchmark is not None:
        eq("benchmark", query.benchmark)
    if query.end_reason is not None:
        eq("end_reason", query.end_reason)
    if query.correct is not None:
        eq("correct", query.correct)
    if query.task:
        conditions.append(pc.match_substring(table["task_id"], query.task))
    if query.reward_min is not None:
        conditions.append(pc.greater_equal(table["reward"], query.reward_min))
    if query.reward_max is not None:
        conditions.append(pc.less_equal(table["reward"], query.reward_max))
    if query.min_severity is not None:
        conditions.append(pc.greater_equal(table["safety_max_severity"], query.min_severity))
    if query.error_kind is not None:
        # list membership: the rows whose error_kinds list holds the value
        kinds = table["error_kinds"].combine_chunks() if table.num_rows else pa.array([], pa.list_(pa.string()))
        hit = pc.filter(pc.list_parent_indices(kinds), pc.equal(pc.list_flatten(kinds), query.error_kind))
        conditions.append(pc.is_in(pa.array(range(table.num_rows), pa.int64()),
                                   value_set=pc.cast(pc.unique(hit), pa.int64())))
    if not conditions:
        return None
    mask = conditions[0]
    for c in conditions[1:]:
        mask = pc.and_kleene(mask, c)
    return pc.fill_null(mask, False)


def _page(table: pa.Table, query: EpisodeQuery) -> dict[str, Any]:
    mask = _mask_for(table, query)
    selected = table if mask is None else table.filter(mask)
    page = selected.slice(query.offset, query.limit)
    return {"total": table.num_rows, "matched": selected.num_rows, "offset": query.offset,
            "rows": page.to_pylist()}


def _facets(table: pa.Table, columns: tuple[str, ...]) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    for c in columns:
        if c not in table.column_names:
            continue
        column = pc.list_flatten(table[c]) if pa.types.is_list(table[c].type) else table[c]
        values = [v for v in pc.unique(column).to_pylist() if v is not None]
        out[c] = sorted(values)
    return out


def per_turn_kl(sample: dict[str, Any]) -> list[float | None]:
    """Per turn, the mean over its trained tokens of log pi_student - log pi_teacher at the sampled
    token: the single-sample estimate of the reverse KL that TT-OPD's distillation term minimises
    (docs/training.md). None for a turn with no trained token or without teacher log-probs."""
    teacher = sample.get("teacher_logprobs")
    if not teacher:
        return [None for _ in sample.get("turns") or []]
    student, mask = sample["sampling_logprobs"], sample["loss_mask"]
    out: list[float | None] = []
    for span in sample.get("turns") or []:
        diffs = [student[p] - teacher[p] for p in range(span["start"], span["end"]) if mask[p]]
        out.append(sum(diffs) / len(diffs) if diffs else None)
    return out


@dataclass
class _Source(ABC):
    """What both kinds of folder share: an id, a path, and a table of episodes built once."""

    id: str
    path: Path
    _facets: dict[str, list[Any]] = field(default_factory=dict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @abstractmethod
    def index(self) -> pa.Table:
        """The episode table of this folder (built once)."""

    def episodes(self, query: EpisodeQuery) -> dict[str, Any]:
        """One page of the episode table under `query`, with the match count and the filter values."""
        out = _page(self.index(), query)
        out["facets"] = self._facets
        return out


@dataclass
class RunSource(_Source):
    """A training run folder."""

    kind: str = "run"
    _index: pa.Table | None = field(default=None, repr=False)

    @staticmethod
    def looks_like(path: Path) -> bool:
        return (path / "metrics.jsonl").is_file() or (path / "trajectories").is_dir()

    def describe(self) -> dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "path": str(self.path), "label": self.path.name}

    def metrics(self) -> dict[str, list[dict[str, Any]]]:
        """Training metrics per step (metrics.jsonl) and validation passes (validation.jsonl)."""
        return {"train": self._jsonl(self.path / "metrics.jsonl"),
                "validation": self._jsonl(self.path / "validation.jsonl")}

    @staticmethod
    def _jsonl(path: Path) -> list[dict[str, Any]]:
        if not path.is_file():
            return []
        rows = []
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue  # a run being written: its last line may be incomplete
            if isinstance(row, dict):
                rows.append(row)
        return rows

    def config_text(self) -> str:
        path = self.path / "config.yaml"
        return path.read_text(encoding="utf-8", errors="replace") if path.is_file() else ""

    def files(self) -> list[tuple[str, Path]]:
        out = []
        for part, folder in (("train", "trajectories"), ("validation", "validation")):
            out.extend((part, p) for p in sorted((self.path / folder).glob("step_*.parquet")))
        return out

    def index(self) -> pa.Table:
        """The episode table of the whole run (built once, on first use, from projected reads)."""
        with self._lock:
            if self._index is None:
                files = self.files()

                def read(item: tuple[int, tuple[str, Path]]) -> pa.Table:
                    number, (part, path) = item
                    table = _current_end_reasons(_read_projected(path, RUN_INDEX_COLUMNS, RUN_INDEX_TYPES))
                    n = table.num_rows
                    return (table.append_column("part", pa.array([part] * n, pa.string()))
                            .append_column("file", pa.array([number] * n, pa.int32()))
                            .append_column("row", pa.array(range(n), pa.int32())))

                with ThreadPoolExecutor(max_workers=4) as pool:
                    tables = list(pool.map(read, enumerate(files)))
                empty = pa.schema([(c, RUN_INDEX_TYPES[c]) for c in RUN_INDEX_COLUMNS]
                                  + [("part", pa.string()), ("file", pa.int32()), ("row", pa.int32())])
                # one chunk per column: kernels over 1,000 small chunks cost several times more
                self._index = pa.concat_tables(tables).combine_chunks() if tables else empty.empty_table()
                self._facets = _facets(self._index, ("part", "domain", "step", "end_reason", "error_kinds",
                                                     "safety_max_severity"))
            return self._index

    def episode(self, file: int, row: int) -> dict[str, Any]:
        files = self.files()
        if not 0 <= file < len(files):
            raise ViewerError(f"run {self.id}: no trajectory file number {file} (the run has {len(files)})")
        part, path = files[file]
        table, index, total = EPISODE_CACHE.row(path, row)
        if index < 0:
            raise ViewerError(f"{path.name}: no row {row} (the file has {total})")
        sample = table.slice(index, 1).to_pylist()[0]
        for name in ("turns", "reward_components", "metadata", "episode"):
            if isinstance(sample.get(name), str):
                sample[name] = json.loads(sample[name])
        sample["turn_kl"] = per_turn_kl(sample)
        sample["hint_text"] = self.hint_text(sample.get("teacher_hint"))
        sample["gold"] = self.gold_answer(sample["domain"], sample["task_id"])
        for name in ("input_ids", "loss_mask", "sampling_logprobs", "teacher_logprobs"):
            sample.pop(name, None)
        sample.update(part=part, file=path.name)
        return sample

    def config(self) -> dict[str, Any]:
        import yaml

        try:
            config = yaml.safe_load(self.config_text()) or {}
        except yaml.YAMLError:
            return {}
        return config if isinstance(config, dict) else {}

    def gold_answer(self, domain: str, task_id: str) -> str | None:
        """The task's gold answer, looked up in the domain the run trained on (None when the task
        or its domain is not available here, e.g. a test domain of another machine)."""
        from envs import registry

        try:
            modules = (self.config().get("data") or {}).get("domain_modules") or {}
            for name, module in modules.items():
                registry.DOMAINS.setdefault(name, module)
            task = next((t for t in registry.get_tasks(domain, None) if t.id == task_id), None)
        except (LookupError, ImportError, ValueError, OSError):
            return None
        return task.correct_answer if task is not None else None

    def hint_text(self, kind: str | None) -> str | None:
        """The privileged hint the teacher was given, as the run's config rendered it."""
        if kind not in ("reinforcing", "corrective"):
            return None
        try:
            hints = ((self.config().get("teacher") or {}).get("hints") or {})
            return str(hints.get("template", "{hint}")).format(hint=hints[kind])
        except (KeyError, AttributeError, IndexError, ValueError):
            return None


@dataclass
class EvalSource(_Source):
    """An evaluation results folder."""

    kind: str = "eval"
    _rows: pa.Table | None = field(default=None, repr=False)
    _results: dict[str, dict[str, Any]] = field(default_factory=dict, repr=False)
    _summary: dict[str, Any] | None = field(default=None, repr=False)

    @staticmethod
    def looks_like(path: Path) -> bool:
        from evals.types import RESULTS_FILE

        return (path / RESULTS_FILE).is_file()

    def describe(self) -> dict[str, Any]:
        from evals.report import read_spec

        spec = read_spec(self.path)
        return {"id": self.id, "kind": self.kind, "path": str(self.path), "label": self.path.name,
                "policy": spec.get("policy_id"), "suite": spec.get("suite"), "condition": spec.get("condition")}

    def index(self) -> pa.Table:
        with self._lock:
            if self._rows is None:
                from evals.metrics import read_results

                rows = read_results(self.path)
                table = {
                    "row_id": [r.get("trajectory_ref", "").split("#")[-1] for r in rows],
                    "benchmark": [r["benchmark"] for r in rows], "domain": [r["domain"] for r in rows],
                    "task_id": [r["task_id"] for r in rows], "condition": [r["condition"] for r in rows],
                    "seed": [r["seed"] for r in rows], "correct": [r.get("correct") for r in rows],
                    "reward": [r.get("reward") for r in rows], "end_reason": [r.get("end_reason") for r in rows],
                    "turns": [r.get("turns", 0) for r in rows], "tool_calls": [r.get("tool_calls", 0) for r in rows],
                    "answer": [r.get("answer") for r in rows], "gold": [r.get("gold") for r in rows],
                    "safety_max_severity": [max((int(k) for k, v in (r.get("safety_violations") or {}).items() if v),
                                                default=0) for r in rows],
                    "error_kinds": [sorted({*(r.get("error_kinds") or {})} | ({r["error_kind"]} if r.get("error_kind")
                                                                              else set())) for r in rows],
                }
                self._rows = pa.table(table)
                self._results = {row_id: r for row_id, r in zip(table["row_id"], rows)}
                self._facets = _facets(self._rows, ("benchmark", "domain", "end_reason", "error_kinds",
                                                    "safety_max_severity"))
            return self._rows

    def summary(self) -> dict[str, Any]:
        with self._lock:
            if self._summary is None:
                from evals.report import summarise_results

                self._summary = summarise_results(self.path, n_resamples=2_000)
            return self._summary

    def episode(self, row_id: str) -> dict[str, Any]:
        from evals.types import TRAJECTORIES_FILE

        self.index()
        result = self._results.get(row_id)
        if result is None:
            raise ViewerError(f"evaluation {self.id}: no episode with row id {row_id!r}")
        messages: list[Any] = []
        path = self.path / TRAJECTORIES_FILE
        if path.is_file():
            table = pq.read_table(path, filters=[("row_id", "=", row_id)])
            if table.num_rows:
                messages = json.loads(table.column("messages")[0].as_py() or "[]")
        return {"result": result, "messages": messages}


Source = RunSource | EvalSource


def discover(paths: list[str | Path]) -> list[Source]:
    """The run and evaluation folders named, or found one level inside a named folder."""
    sources: list[Source] = []
    seen: set[Path] = set()

    def add(path: Path) -> bool:
        path = path.resolve()
        if path in seen:
            return True
        for cls in (EvalSource, RunSource):
            if cls.looks_like(path):
                seen.add(path)
                sources.append(cls(id=f"s{len(sources)}", path=path))
                return True
        return False

    for raw in paths:
        path = Path(raw)
        if not path.is_dir():
            raise ViewerError(f"{path}: not a folder (expected a run folder written by `hcgym train` or an "
                              "evaluation folder written by `hcgym eval`)")
        if not add(path):
            found = [add(child) for child in sorted(path.iterdir()) if child.is_dir()]
            if not any(found):
                raise ViewerError(f"{path}: neither a run folder (metrics.jsonl, trajectories/) nor an evaluation "
                                  "folder (results.parquet), and no such folder inside it")
    return sources
