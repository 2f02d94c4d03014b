"""Shared machinery for converters: readers that keep file line numbers, and the result type.

Every reader here takes benchmark files as users really have them (../shared/reference/benchmark_layouts.md):
UTF-8 with or without a byte-order mark, LF or CRLF line ends, plain or gzip-compressed (`.gz`). Anything
else stops with a `SourceFileError` that names the file and the line: another encoding (Latin-1 bytes that
are not UTF-8), a truncated or damaged gzip stream. Rows are decoded one line at a time, so a bad byte is
reported on its own line and a large file (MIMIC-III LABEVENTS) is streamed, never held whole.
"""

from __future__ import annotations

import csv
import gzip
import json
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from envs.core.task import Task

BOM = b"\xef\xbb\xbf"


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
    # rows read from the source (data rows / records), for the import table (read / imported / rejected)
    rows_read: int = 0

    def add_error(self, path: Path, line: int, message: str) -> None:
        self.errors.append(RowError(str(path), line, message))


class SourceFileError(ValueError):
    """The whole file cannot be read (missing, wrong top-level shape, not UTF-8, damaged gzip)."""


def _require_file(path: Path) -> None:
    if not path.exists():
        raise SourceFileError(f"{path}: file not found")
    if not path.is_file():
        raise SourceFileError(f"{path}: not a file")


def _decode(raw: bytes, path: Path, line: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        byte = raw[exc.start]
        raise SourceFileError(
            f"{path}:{line}: not UTF-8 (byte 0x{byte:02x} at column {exc.start + 1}); the file looks like another "
            "encoding (e.g. Latin-1 / Windows-1252): re-save it as UTF-8") from None


def iter_lines(path: Path) -> Iterator[tuple[int, str]]:
    """(1-based line number, text with its line end) for every line of a UTF-8 file, `.gz` decompressed.

    The BOM is dropped from the first line; CRLF is kept (csv handles it, `str.strip` removes it)."""
    _require_file(path)
    opener = gzip.open if path.name.endswith(".gz") else open
    number = 0
    try:
        with opener(path, "rb") as handle:
            for number, raw in enumerate(handle, start=1):
                if number == 1 and raw.startswith(BOM):
                    raw = raw[len(BOM):]
                yield number, _decode(raw, path, number)
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise SourceFileError(f"{path}:{number + 1}: damaged or truncated gzip file ({type(exc).__name__}: {exc}); "
                              "download it again") from None


def read_text(path: Path) -> str:
    """The whole file as text (see `iter_lines` for what is accepted)."""
    return "".join(text for _, text in iter_lines(path))


def iter_parquet(path: Path, result: ConversionResult) -> Iterator[tuple[int, dict[str, Any]]]:
    """(row number, record) for each row of a parquet file (Hugging Face's own layout of MedMCQA, MMLU,
    ...): the same records as the JSON lines, with integers kept as integers."""
    _require_file(path)
    try:
        import pyarrow.parquet as pq
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        raise SourceFileError(f"{path}: reading parquet needs pyarrow (pip install pyarrow)") from None
    try:
        parquet = pq.ParquetFile(path)
        batches = parquet.iter_batches(batch_size=4096)  # a batch at a time: never the whole table as Python objects
        number = 0
        for batch in batches:
            for record in batch.to_pylist():
                number += 1
                result.rows_read += 1
                yield number, record
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid / ArrowIOError derive from these
        raise SourceFileError(f"{path}: not a readable parquet file ({type(exc).__name__}: {exc})") from None


def iter_jsonl(path: Path, result: ConversionResult) -> Iterator[tuple[int, dict[str, Any]]]:
    """Yield (line number, object) for each non-empty line; bad lines go to `result.errors`.
    A `.parquet` file yields its rows (numbered from 1) instead."""
    if path.name.endswith(".parquet"):
        yield from iter_parquet(path, result)
        return
    for number, line in iter_lines(path):
        if not line.strip():
            continue
        result.rows_read += 1
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
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise SourceFileError(f"{path}:{exc.lineno}: not valid JSON at line {exc.lineno} column {exc.colno}: "
                              f"{exc.msg}") from None


def _line_at(text: str, position: int, cache: list[int]) -> int:
    """1-based line of `position`; `cache` = [last position, its line] so a forward scan stays linear."""
    last_pos, last_line = cache
    if position < last_pos:
        last_pos, last_line = 0, 1
    line = last_line + text.count("\n", last_pos, position)
    cache[0], cache[1] = position, line
    return line


def iter_json_array(path: Path, text: str, result: ConversionResult,
                    what: str = "item") -> Iterator[tuple[int, int, Any]]:
    """(item index 1-based, file line, value) for each item of a top-level JSON array.

    Items are decoded one by one, so a damaged item is reported with its index and the line it starts
    on, and the items before it are kept."""
    decoder = json.JSONDecoder()
    ws = " \t\r\n"
    position = len(text) - len(text.lstrip(ws))
    if not text.startswith("[", position):
        raise SourceFileError(f"{path}: expected a JSON array")
    position += 1
    cache = [0, 1]
    index = 0
    while True:
        while position < len(text) and text[position] in ws:
            position += 1
        if position >= len(text):
            raise SourceFileError(f"{path}:{_line_at(text, position, cache)}: the JSON array is not closed "
                                  f"(file truncated after {what} {index}?)")
        if text[position] == "]":
            return
        if index:
            if text[position] != ",":
                raise SourceFileError(f"{path}:{_line_at(text, position, cache)}: expected ',' or ']' after "
                                      f"{what} {index}")
            position += 1
            while position < len(text) and text[position] in ws:
                position += 1
        index += 1
        line = _line_at(text, position, cache)
        result.rows_read += 1
        try:
            value, position = decoder.raw_decode(text, position)
        except json.JSONDecodeError as exc:
            raise SourceFileError(f"{path}:{exc.lineno}: {what} {index} (starting on line {line}) is not valid JSON: "
                                  f"{exc.msg} at line {exc.lineno} column {exc.colno}; the {index - 1} "
                                  f"{what}s before it were read") from None
        yield index, line, value


def iter_json_records(path: Path, result: ConversionResult) -> Iterator[tuple[int, dict[str, Any]]]:
    """A JSON array of objects or, failing that, JSON lines: (file line, object).

    For an array, errors name the item index and its file line ("item 3: ..."). A `.parquet` file yields
    its rows."""
    if path.name.endswith(".parquet"):
        yield from iter_parquet(path, result)
        return
    text = read_text(path)
    if text.lstrip().startswith("["):
        for index, line, obj in iter_json_array(path, text, result):
            if not isinstance(obj, dict):
                result.add_error(path, line, f"item {index}: expected a JSON object, got {type(obj).__name__}")
                continue
            obj = dict(obj)
            obj["__item__"] = index
            yield line, obj
    else:
        yield from iter_jsonl(path, result)


def csv_rows(path: Path, lines: Iterable[tuple[int, str]] | None = None) -> Iterator[tuple[int, list[str] | None, str]]:
    """(first line of the record, fields or None, CSV error message) over a CSV file: quoted fields may hold
    commas and newlines (MMLU's questions do); the line reported is the line the record starts on."""
    source = iter(lines if lines is not None else iter_lines(path))
    state = {"line": 0}

    def feed() -> Iterator[str]:
        for number, text in source:
            state["line"] = number
            yield text

    reader = csv.reader(feed())
    while True:
        start = state["line"] + 1
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            yield start, None, f"CSV error: {exc}"
            continue
        yield start, row, ""


def iter_csv(path: Path, result: ConversionResult, *, expected_columns: int,
             lines: Iterable[tuple[int, str]] | None = None) -> Iterator[tuple[int, list[str]]]:
    for line, row, problem in csv_rows(path, lines):
        if row is None:
            result.rows_read += 1
            result.add_error(path, line, problem)
            continue
        if not row or all(not cell.strip() for cell in row):
            continue
        result.rows_read += 1
        if len(row) != expected_columns:
            result.add_error(path, line, f"expected {expected_columns} columns, got {len(row)}")
            continue
        yield line, row


def require(obj: dict[str, Any], keys: list[str]) -> str | None:
    """The first missing or empty key, or None."""
    for key in keys:
        value = obj.get(key)
        if value is None or (isinstance(value, str) and not value.strip()):
            return key
    return None


def confined_image(images: Path, name: str) -> tuple[Path | None, str | None]:
    """The image file `name` inside the folder `images` (trying .jpg/.png/.jpeg when `name` has no extension).

    Returns (path, None) or (None, the reason): a name that is absolute or climbs out of the folder
    (`../../etc/passwd`, a symlink pointing elsewhere) is refused, so an imported task never points the
    policy at a file outside the image folder the user named."""
    root = images.resolve()
    if not name.strip():
        return None, "empty image name"
    if Path(name).is_absolute() or "\x00" in name:
        return None, f"image {name!r} is not a path inside the image folder {images}"
    candidates = [images / name] + [images / f"{name}{ext}" for ext in (".jpg", ".png", ".jpeg")]
    for candidate in candidates:
        resolved = candidate.resolve()
        if not resolved.is_relative_to(root):
            return None, f"image {name!r} escapes the image folder {images} (resolves to {resolved})"
        if resolved.is_file():
            return resolved, None
    return None, f"image {name!r} not found in {images}"
