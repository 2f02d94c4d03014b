"""SQLite passage store: the passages themselves (text, metadata, provenance) keyed by row.

Row ``r`` (1-based SQLite rowid) is document ``r - 1`` of both search indexes. The store is
written once by the builder (dedup by doc_id, resumable progress per input) and then opened
read-only and immutable by any number of processes.

A passage's content of `COMPRESS_MIN_BYTES` or more is stored zlib-compressed, as a BLOB; shorter
content stays TEXT. The column's storage class says which, row by row, so a store written before
compression (all TEXT) reads the same. Whoever reads ``content`` with SQL of their own passes it
through `decode_content` (or `indexed_text`).
"""

from __future__ import annotations

import json
import numbers
import sqlite3
import threading
import zlib
from pathlib import Path
from typing import Iterable, Iterator

SCHEMA = """
CREATE TABLE IF NOT EXISTS passages(
    rowid INTEGER PRIMARY KEY,
    doc_id TEXT NOT NULL UNIQUE,
    source TEXT NOT NULL,
    title TEXT NOT NULL,
    content TEXT NOT NULL,
    category TEXT NOT NULL,
    dataset_name TEXT NOT NULL,
    prov_id INTEGER
);
CREATE TABLE IF NOT EXISTS provenance(id INTEGER PRIMARY KEY, json TEXT NOT NULL UNIQUE);
CREATE TABLE IF NOT EXISTS ingest_progress(
    input TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, rows_done INTEGER NOT NULL,
    done INTEGER NOT NULL DEFAULT 0, inserted INTEGER NOT NULL DEFAULT 0,
    duplicates INTEGER NOT NULL DEFAULT 0, rejected INTEGER NOT NULL DEFAULT 0
);
"""

ROW_COLUMNS = "rowid, doc_id, source, title, content, category, dataset_name, prov_id"
CONTENT_COLUMN = ROW_COLUMNS.split(", ").index("content")
MMAP_BYTES = 1 << 40
# Abstract-length passages (PubMed, StatPearls, textbook chunks: 1-3 KB) are most of a large store
# and shrink to about half; short ones (ICD-10-CM entries, drug label lines) would gain little over
# zlib's header. Level 3 compressed 296-word passages as well as level 6 at 0.8x its time.
COMPRESS_MIN_BYTES = 256
ZLIB_LEVEL = 3


def encode_content(text: str) -> str | bytes:
    """What the store keeps for `text`: zlib-compressed UTF-8 when long enough to gain, else `text`."""
    raw = text.encode("utf-8")
    if len(raw) < COMPRESS_MIN_BYTES:
        return text
    packed = zlib.compress(raw, ZLIB_LEVEL)
    return packed if len(packed) < len(raw) else text


def decode_content(value: str | bytes) -> str:
    """A passage's text from its stored ``content`` (`encode_content`'s output, or plain TEXT)."""
    return zlib.decompress(value).decode("utf-8") if isinstance(value, bytes) else value


def indexed_text(title: str, content: str | bytes) -> str:
    """The text both indexes analyse for a passage: its title, a newline, its content."""
    text = decode_content(content)
    return f"{title}\n{text}" if title else text


def _decoded(row: tuple | None) -> tuple | None:
    """A `ROW_COLUMNS` row with its content as text."""
    if row is None or not isinstance(row[CONTENT_COLUMN], bytes):
        return row
    return (*row[:CONTENT_COLUMN], decode_content(row[CONTENT_COLUMN]), *row[CONTENT_COLUMN + 1:])


def check_text(argument: str, value: object) -> str:
    """`value` if it is a str SQLite can bind; a clear error naming `argument` otherwise.

    A lone surrogate (U+D800-U+DFFF, e.g. from JSON "\\ud800" or a bad decode) is valid in a Python
    str but has no UTF-8 encoding: SQLite would fail with a bare UnicodeEncodeError.

    Raises:
        TypeError: `value` is not a str.
        ValueError: `value` holds a lone surrogate (its position is named).
    """
    if not isinstance(value, str):
        raise TypeError(f"{argument} must be a str, got {type(value).__name__}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise ValueError(f"{argument} holds a lone surrogate (U+{ord(value[exc.start]):04X}) at position {exc.start}; "
                         f"it is not valid Unicode text") from None
    return value


class StoreWriter:
    """Appends passages; `INSERT OR IGNORE` on the unique doc_id deduplicates (first wins)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.conn = sqlite3.connect(str(self.path))
        self.conn.execute("PRAGMA journal_mode=WAL")
        self.conn.execute("PRAGMA synchronous=NORMAL")
        self.conn.executescript(SCHEMA)
        self._prov: dict[str, int] = {j: i for i, j in self.conn.execute("SELECT id, json FROM provenance")}

    def provenance_id(self, prov: dict | None) -> int | None:
        if not prov:
            return None
        key = json.dumps(prov, sort_keys=True, ensure_ascii=False)
        pid = self._prov.get(key)
        if pid is None:
            cur = self.conn.execute("INSERT INTO provenance(json) VALUES (?)", (key,))
            pid = self._prov[key] = int(cur.lastrowid)
        return pid

    def insert_many(self, rows: list[tuple]) -> int:
        """rows: (doc_id, source, title, content, category, dataset_name, prov_id). Returns inserted."""
        before = self.conn.total_changes
        self.conn.executemany(
            "INSERT OR IGNORE INTO passages(doc_id, source, title, content, category, dataset_name, prov_id)"
            " VALUES (?,?,?,?,?,?,?)",
            ((doc_id, source, title, encode_content(content), *rest) for doc_id, source, title, content, *rest in rows),
        )
        return self.conn.total_changes - before

    def progress(self, name: str) -> dict | None:
        row = self.conn.execute(
            "SELECT fingerprint, rows_done, done, inserted, duplicates, rejected FROM ingest_progress WHERE input=?",
            (name,),
        ).fetchone()
        if row is None:
            return None
        keys = ("fingerprint", "rows_done", "done", "inserted", "duplicates", "rejected")
        return dict(zip(keys, row))

    def set_progress(self, name: str, fingerprint: str, rows_done: int, done: bool, inserted: int,
                     duplicates: int, rejected: int) -> None:
        self.conn.execute(
            "INSERT OR REPLACE INTO ingest_progress VALUES (?,?,?,?,?,?,?)",
            (name, fingerprint, rows_done, int(done), inserted, duplicates, rejected),
        )

    def commit(self) -> None:
        self.conn.commit()

    def count(self) -> int:
        return int(self.conn.execute("SELECT count(*) FROM passages").fetchone()[0])

    def source_counts(self) -> dict[str, int]:
        return dict(self.conn.execute("SELECT source, count(*) FROM passages GROUP BY source ORDER BY source"))

    def iter_rows(self, batch: int = 20_000, after: int = 0) -> Iterator[list[tuple]]:
        """Batches of (rowid, doc_id, source, title, content, category, dataset_name, prov_id) by rowid,
        from the row after `after` (a resumed index build skips the rows it has committed)."""
        last = after
        while True:
            rows = self.conn.execute(
                f"SELECT {ROW_COLUMNS} FROM passages WHERE rowid > ? ORDER BY rowid LIMIT ?", (last, batch)
            ).fetchall()
            if not rows:
                return
            last = rows[-1][0]
            yield [_decoded(r) for r in rows]

    def finalize(self) -> None:
        """Check rows are 1..N with no gaps (they are the index's document numbers), then compact."""
        n, lo, hi = self.conn.execute("SELECT count(*), min(rowid), max(rowid) FROM passages").fetchone()
        if n and (lo != 1 or hi != n):
            raise RuntimeError(f"{self.path}: passage rows are not contiguous (n={n}, min={lo}, max={hi})")
        self.conn.commit()
        self.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        self.conn.execute("PRAGMA journal_mode=DELETE")
        self.conn.commit()

    def close(self) -> None:
        self.conn.close()


class StoreReader:
    """Read-only, immutable access from many threads and processes."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._local = threading.local()
        conn = self._conn()
        self.provenance = {i: json.loads(j) for i, j in conn.execute("SELECT id, json FROM provenance")}

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(f"file:{self.path}?mode=ro&immutable=1", uri=True, check_same_thread=False)
            # Read pages through a memory map (shared with every process's page cache) instead of
            # a read() copy per page: fetching a search's 10 rows went from 0.37 to 0.15 ms at
            # the median over 828K passages. SQLite caps the size at its compile-time limit.
            conn.execute(f"PRAGMA mmap_size={MMAP_BYTES}")
            self._local.conn = conn
        return conn

    def max_rowid(self) -> int:
        return int(self._conn().execute("SELECT coalesce(max(rowid), 0) FROM passages").fetchone()[0])

    def rows_by_index(self, doc_indices: Iterable[int]) -> dict[int, tuple]:
        """{doc index: row} for 0-based document indices (indices past the last row are absent).

        Raises:
            TypeError / ValueError: naming `doc_indices` for an entry that is not a non-negative integer.
        """
        ids = []
        for position, index in enumerate(doc_indices):
            # numpy integers count; booleans and floats (inf included) do not.
            if isinstance(index, bool) or not isinstance(index, numbers.Integral):
                raise TypeError(f"doc_indices[{position}] must be an integer, got {type(index).__name__}")
            if not 0 <= index < 1 << 62:  # SQLite rowids are 64-bit
                raise ValueError(f"doc_indices[{position}] must be a document number >= 0, got {index}")
            ids.append(int(index) + 1)
        if not ids:
            return {}
        marks = ",".join("?" * len(ids))
        rows = self._conn().execute(f"SELECT {ROW_COLUMNS} FROM passages WHERE rowid IN ({marks})", ids)
        return {r[0] - 1: _decoded(r) for r in rows}

    def row_by_doc_id(self, doc_id: str) -> tuple | None:
        """The row of `doc_id`, or None. Raises TypeError / ValueError naming `doc_id` (see `check_text`)."""
        check_text("doc_id", doc_id)
        return _decoded(self._conn().execute(f"SELECT {ROW_COLUMNS} FROM passages WHERE doc_id = ?",
                                             (doc_id,)).fetchone())

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None
