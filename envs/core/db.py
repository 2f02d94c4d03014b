"""The domain database base class: strict pydantic, JSON load/dump, a stable content hash."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, ClassVar, Self

from pydantic import BaseModel, ConfigDict, PrivateAttr, ValidationError


class DataFileError(ValueError):
    """A data file (database, tasks) is missing or malformed; the message names file and field."""


def read_text_file(path: str | Path, what: str) -> str:
    """The UTF-8 text of a data file (a leading BOM is dropped); every failure names the file.

    Args:
        path: The file.
        what: What the file is, for the message ("task file", "database file", ...).

    Raises:
        DataFileError: missing, unreadable, or not UTF-8 (with the line and byte offset of the
            first bad byte, so a Latin-1 or UTF-16 file is found without a hex editor).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise DataFileError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        # utf-8-sig: files saved by Windows editors start with a BOM; the text itself is the same.
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise DataFileError(f"{path}: {what} is not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line}, "
                            f"offset {exc.start}); re-save it as UTF-8") from None


def _refuse_repeats(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise _RepeatedKey(key)
        seen[key] = value
    return seen


class _RepeatedKey(ValueError):
    pass


def read_json_file(path: str | Path, what: str, *, refuse_repeated_keys: bool = False) -> Any:
    """Parse a JSON data file; every failure names the file (and the line and column of a syntax error).

    `refuse_repeated_keys`: an object with the same key twice is an error (JSON keeps the last one
    silently), for hand-written files where the repeat is a mistake.

    Raises:
        DataFileError: see `read_text_file`, plus invalid JSON, nesting too deep to parse, a
            number too long to convert (Python's int limit), or a repeated key.
    """
    text = read_text_file(path, what)
    try:
        return json.loads(text, object_pairs_hook=_refuse_repeats if refuse_repeated_keys else None)
    except _RepeatedKey as exc:
        raise DataFileError(f"{path}: {what} repeats the key {exc.args[0]!r} in one object") from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}: not valid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise DataFileError(f"{path}: {what} is nested too deeply to parse") from None
    except ValueError as exc:  # e.g. an integer literal over sys.get_int_max_str_digits() digits
        raise DataFileError(f"{path}: {what} holds a value JSON cannot convert ({exc})") from None


def format_validation_error(exc: ValidationError, *, source: str, item: str | None = None) -> str:
    """One line per problem: `file [item] field.path: message (got value)`."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "<root>"
        got = "" if err["type"] == "missing" else f" (got {repr(err.get('input'))[:60]})"
        prefix = f"{source}" + (f" [{item}]" if item else "")
        lines.append(f"{prefix} field {loc!r}: {err['msg']}{got}")
    return "\n".join(lines)


class DB(BaseModel):
    """Base of every domain database. Unknown fields are errors, never silently dropped."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    @classmethod
    def load(cls, path: str | Path) -> Self:
        path = Path(path)
        if not path.exists():
            raise DataFileError(f"{path}: database file not found (run `hcgym data build`)")
        raw = read_json_file(path, "database file")
        try:
            return cls.model_validate(raw)
        except ValidationError as exc:
            raise DataFileError(format_validation_error(exc, source=str(path))) from None

    def dump(self, path: str | Path) -> None:
        """Write deterministic JSON (sorted keys) so rebuilds produce identical files."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(
            json.dumps(self.model_dump(mode="json"), sort_keys=True, ensure_ascii=False, indent=1) + "\n",
            encoding="utf-8",
        )

    def __deepcopy__(self, memo: dict | None = None) -> Self:
        # The toolkit snapshots the database before every WRITE call; a JSON round trip through
        # pydantic's Rust core is several times faster than a generic deepcopy of nested models.
        return type(self).model_validate_json(self.model_dump_json())

    def content_hash(self) -> str:
        """SHA-256 of the canonical JSON: equal states hash equal, whatever the insertion order."""
        canonical = json.dumps(self.model_dump(mode="json"), sort_keys=True, ensure_ascii=False, separators=(",", ":"))
        return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def _plain(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _canonical(payload: Any) -> str:
    return json.dumps(payload, sort_keys=True, ensure_ascii=False, separators=(",", ":"))


class ForkableDB(DB):
    """A database split into read-only reference tables and per-episode state.

    Episodes `fork()` the parsed template: the reference tables (patients, studies, formularies)
    are shared, the state fields (orders, notes, reports) are copied, so reset, the WRITE snapshot
    and hashing cost only the state. Subclasses name the two groups:

        REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ("patients", "formulary")
        STATE_FIELDS: ClassVar[tuple[str, ...]] = ("orders", "notes")

    Tools must not mutate reference tables (they are shared between episodes).
    """

    REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ()
    STATE_FIELDS: ClassVar[tuple[str, ...]] = ()
    _reference_hash: str | None = PrivateAttr(default=None)

    def reference_hash(self) -> str:
        if self._reference_hash is None:
            payload = _canonical({f: _plain(getattr(self, f)) for f in self.REFERENCE_FIELDS})
            self._reference_hash = hashlib.sha256(payload.encode("utf-8")).hexdigest()
        return self._reference_hash

    def fork(self) -> Self:
        """A copy sharing the reference tables, with its own deep copy of the state fields."""
        state = {f: _copy_state(getattr(self, f)) for f in self.STATE_FIELDS}
        clone = type(self).model_construct(**{f: getattr(self, f) for f in self.REFERENCE_FIELDS}, **state)
        clone._reference_hash = self.reference_hash()
        return clone

    def __deepcopy__(self, memo: dict | None = None) -> Self:
        return self.fork()

    def content_hash(self) -> str:
        """SHA-256 over the reference hash and the canonical JSON of the state."""
        state = _canonical({f: _plain(getattr(self, f)) for f in self.STATE_FIELDS})
        return hashlib.sha256((self.reference_hash() + state).encode("utf-8")).hexdigest()


def _copy_state(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_copy(deep=True)
    if isinstance(value, dict):
        return {k: _copy_state(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_state(v) for v in value]
    return value
