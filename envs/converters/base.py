"""Shared machinery for converters: row readers that keep line numbers, and the result type."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from envs.core.task import Task


@dataclass
class RowError:
    path: str
    line: int
    message: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.message}"


@dataclass
class ConversionResult:
    tasks: list[Task] = field(default_factory=list)
    errors: list[RowError] = field(default_factory=list)
    # file-level facts the user must see in the import summary (e.g. which MedMCQA `cop` base was assumed)
    notes: list[str] = field(default_factory=list)

    def add_error(self, path: Path, line: int, message: str) -> None:
        self.errors.append(RowError(str(path), line, message))


class SourceFileError(ValueError):
    """The whole file cannot be read (missing, wrong top-level shape)."""


def iter_jsonl(path: Path, result: ConversionResult) -> Iterator[tuple[int, dict[str, Any]]]:
    """Yield (line number, object) for each non-empty line; bad lines go to `result.errors`."""
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    with path.open(encoding="utf-8") as handle:
        for number, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as exc:
                result.add_error(path, number, f"not valid JSON: {exc.msg} at column {exc.colno}")
                continue
            if not isinstance(obj, dict):
                result.add_error(path, number, f"expected a JSON object, got {type(obj).__name__}")
                continue
            yield number, obj


def load_json(path: Path) -> Any:
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SourceFileError(f"{path}: not valid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None


def iter_json_records(path: Path, result: ConversionResult) -> Iterator[tuple[int, dict[str, Any]]]:
    """A JSON array of objects (item index as the 'line', 1-based) or, failing that, JSON lines."""
    text = path.read_text(encoding="utf-8") if path.exists() else None
    if text is None:
        raise SourceFileError(f"{path}: file not found")
    stripped = text.lstrip()
    if stripped.startswith("["):
        data = load_json(path)
        for index, obj in enumerate(data, start=1):
            if not isinstance(obj, dict):
                result.add_error(path, index, f"item {index}: expected a JSON object, got {type(obj).__name__}")
                continue
            yield index, obj
    else:
        yield from iter_jsonl(path, result)


def iter_csv(path: Path, result: ConversionResult, *, expected_columns: int) -> Iterator[tuple[int, list[str]]]:
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    with path.open(encoding="utf-8", newline="") as handle:
        reader = csv.reader(handle)
        while True:
            try:
                row = next(reader)
            except StopIteration:
                return
            except csv.Error as exc:
                result.add_error(path, reader.line_num, f"CSV error: {exc}")
                continue
            if not row or all(not cell.strip() for cell in row):
                continue
            if len(row) != expected_columns:
                result.add_error(path, reader.line_num, f"expected {expected_columns} columns, got {len(row)}")
                continue
            yield reader.line_num, row


def require(obj: dict[str, Any], keys: list[str]) -> str | None:
    """The first missing or empty key, or None."""
    for key in keys:
        value = obj.get(key)
        if value is None or (isinstance(value, str) and not value.strip()):
            return key
    return None
