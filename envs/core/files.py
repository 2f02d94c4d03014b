"""Writing files so that readers never see half of one, and a failure leaves nothing behind; a full
disk reported as such (`DiskFullError`, naming the file); damaged Parquet files named in their error."""

from __future__ import annotations

import errno
import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

# errno values that mean "no room": out of blocks or inodes (ENOSPC), over a quota (EDQUOT).
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
# Libraries that lose the errno on the way up (torch.save: "basic_ios::clear: iostream error",
# sqlite: "database or disk is full", pyarrow: "Error writing bytes to file") still fail on a
# filesystem with next to nothing free: a failed write there is taken for a full disk.
NEARLY_FULL_BYTES = 1 << 20
_FULL_MESSAGES = ("no space left on device", "disk quota exceeded", "database or disk is full")


class DiskFullError(OSError):
    """A write ran out of space. The message names the file, says that its disk is full and how
    much the filesystem has free, then (`hint`) what was kept and how to go on.

    Args:
        path: The file (or folder) being written.
        free_bytes: Free bytes on its filesystem when the write failed (None: unknown).
        cause: The underlying error, in one line.
        hint: What the caller kept and how to continue after freeing space.
    """

    def __init__(self, path: str | os.PathLike, free_bytes: int | None = None, cause: str = "",
                 hint: str = "") -> None:
        self.path = Path(path)
        self.free_bytes = free_bytes
        self.cause_text = cause
        self.hint = hint
        free = "free space unknown" if free_bytes is None else f"{free_bytes:,} bytes free on its filesystem"
        message = f"{self.path}: the disk is full ({free}"
        message += f"; {cause})" if cause else ")"
        if hint:
            message += f". {hint}"
        super().__init__(errno.ENOSPC, message)
        self.message = message

    def __str__(self) -> str:
        return self.message

    def __reduce__(self):  # crosses process boundaries (Ray actors) with its fields intact
        return (type(self), (str(self.path), self.free_bytes, self.cause_text, self.hint))

    def with_hint(self, hint: str) -> "DiskFullError":
        """The same error with `hint` (what was kept, how to go on) after the cause."""
        return DiskFullError(self.path, self.free_bytes, self.cause_text, hint)


def free_bytes(path: str | os.PathLike) -> int | None:
    """Free bytes on the filesystem holding `path` (or its nearest existing parent); None if unknown."""
    where = Path(path)
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        return shutil.disk_usage(where).free
    except OSError:
        return None


def _chain(exc: BaseException) -> Iterator[BaseException]:
    """`exc`, then what it wraps: a Ray task error's `cause`, `__cause__`, `__context__`."""
    seen: set[int] = set()
    todo = [exc]
    while todo and len(seen) < 16:
        current = todo.pop(0)
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        yield current
        todo.extend([getattr(current, "cause", None), current.__cause__, current.__context__])


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:240]}" if text else type(exc).__name__


def as_disk_full(exc: BaseException, path: str | os.PathLike) -> DiskFullError | None:
    """`exc` as a `DiskFullError` about `path` when it is one, else None.

    A `DiskFullError` anywhere in the chain (e.g. raised inside a Ray actor) is returned as it is
    (it already names its file). Otherwise: an `OSError` with ENOSPC / EDQUOT, an error whose text
    says the disk is full, or a failed write (`OSError`, `RuntimeError`, sqlite's errors) on a
    filesystem with less than `NEARLY_FULL_BYTES` free.
    """
    if not isinstance(exc, Exception):
        return None
    chain = list(_chain(exc))
    for item in chain:
        if isinstance(item, DiskFullError) and type(item) is DiskFullError:
            return item
        if isinstance(item, DiskFullError):  # Ray's dual-class wrapper: its fields are on `cause`
            inner = getattr(item, "cause", None)
            if type(inner) is DiskFullError:
                return inner
    free = free_bytes(path)
    for item in chain:
        if isinstance(item, OSError) and item.errno in DISK_FULL_ERRNOS:
            return DiskFullError(path, free, _one_line(item))
        if any(text in str(item).lower() for text in _FULL_MESSAGES):
            return DiskFullError(path, free, _one_line(item))
    failed_write = any(isinstance(item, (OSError, RuntimeError)) or type(item).__module__ == "sqlite3"
                       for item in chain)
    if failed_write and free is not None and free < NEARLY_FULL_BYTES:
        return DiskFullError(path, free, _one_line(exc))
    return None


@contextmanager
def naming_full_disk(path: str | os.PathLike) -> Iterator[None]:
    """Re-raise an error of the body that is a full disk (`as_disk_full`) as a `DiskFullError`
    naming `path`; any other error passes through unchanged."""
    try:
        yield
    except Exception as exc:
        full = as_disk_full(exc, path)
        if full is None or full is exc:
            raise
        raise full from exc


def replace_atomic(path: str | os.PathLike, write: Callable[[Path], None]) -> None:
    """`write(tmp)` then rename over `path`, so readers never see half a file; the temporary file
    (`.NAME.tmp` next to `path`) is removed if anything fails, and the previous file stays.

    Raises:
        DiskFullError: naming `path`, when the write ran out of space.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        full = as_disk_full(exc, path)  # before the unlink gives the space back
        tmp.unlink(missing_ok=True)
        if full is not None and full is not exc:
            raise full from exc
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 text atomically (see `replace_atomic`)."""
    replace_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def append_durable(path: str | os.PathLike, data: bytes) -> None:
    """Append `data` to `path` and fsync it. A write that fails (a full disk) cuts the file back to
    its previous length, so an append-only file never keeps half a record.

    Raises:
        DiskFullError: naming `path`, when the append ran out of space.
    """
    path = Path(path)
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        except OSError as exc:
            full = as_disk_full(exc, path)
            try:
                os.ftruncate(fd, size)
            except OSError:
                pass  # the torn tail stays; readers cut a torn last line (learner.metrics.read_jsonl_rows)
            if full is not None:
                raise full from exc
            raise
    finally:
        os.close(fd)


def read_parquet(path: str | os.PathLike, **kwargs: Any):
    """`pyarrow.parquet.read_table(path)`; a damaged file (bit flips, cut short) raises a
    `ValueError` naming it instead of pyarrow's bare "Couldn't deserialize thrift".

    Raises:
        FileNotFoundError: the file is missing.
        ValueError: naming the file, when it is not a readable Parquet file.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such Parquet file")
    try:
        return pq.read_table(str(path), **kwargs)
    except PermissionError:
        raise
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable Parquet file, damaged or cut short "
                         f"({_one_line(exc)})") from None
