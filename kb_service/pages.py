"""Wikipedia-style article store: full articles by title or URL, from a compressed file.

Layout of a store directory:

* ``pages.zlib``: a sequence of independently zlib-compressed blocks; each block holds the
  UTF-8 text of consecutive articles (about 256 KB before compression).
* ``pages.sqlite``: one row per article: title, normalised title key, URL, the block's byte
  offset and length in ``pages.zlib``, and the article's offset and length inside the block.

Reading an article is one indexed SQLite lookup, one ``pread`` of its block and one block
decompression (about a millisecond), whatever the number of articles: the paper's 26M-article
store works the same way (see docs/kb.md for sizes). Ingestion streams JSONL lines of
``{"url", "title", "text"}`` in constant memory; a repeated title keeps the first article.
"""

from __future__ import annotations

import gzip
import json
import os
import sqlite3
import threading
import unicodedata
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

BLOCK_BYTES = 256 * 1024
DATA_FILE = "pages.zlib"
INDEX_FILE = "pages.sqlite"


def title_key(title: str) -> str:
    """Case-, accent- and spacing-insensitive key: 'Heart_failure' == 'heart failure'."""
    text = unicodedata.normalize("NFKD", title.replace("_", " "))
    text = "".join(c for c in text if not unicodedata.combining(c))
    return " ".join(text.casefold().split())


@dataclass
class Article:
    title: str
    url: str
    text: str


class PageStoreWriter:
    def __init__(self, directory: Path) -> None:
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        for name in (DATA_FILE, INDEX_FILE):
            if (self.dir / name).exists():
                (self.dir / name).unlink()
        self.data = open(self.dir / DATA_FILE, "wb")
        self.db = sqlite3.connect(str(self.dir / INDEX_FILE))
        self.db.executescript(
            "CREATE TABLE pages(id INTEGER PRIMARY KEY, title TEXT NOT NULL, key TEXT NOT NULL UNIQUE, url TEXT,"
            " block_off INTEGER NOT NULL, block_len INTEGER NOT NULL, off INTEGER NOT NULL, len INTEGER NOT NULL);"
        )
        self._block: list[bytes] = []
        self._block_size = 0
        self._pending: list[tuple] = []
        self._keys: set[str] = set()
        self.count = 0
        self.duplicates = 0

    def add(self, title: str, text: str, url: str = "") -> bool:
        key = title_key(title)
        if not key or key in self._keys or self.db.execute("SELECT 1 FROM pages WHERE key=?", (key,)).fetchone():
            self.duplicates += 1
            return False
        self._keys.add(key)
        raw = text.encode("utf-8")
        self._pending.append((title, key, url or "", self._block_size, len(raw)))
        self._block.append(raw)
        self._block_size += len(raw)
        self.count += 1
        if self._block_size >= BLOCK_BYTES:
            self._flush()
        return True

    def _flush(self) -> None:
        if not self._block:
            return
        comp = zlib.compress(b"".join(self._block), 6)
        off = self.data.tell()
        self.data.write(comp)
        self.db.executemany(
            "INSERT INTO pages(title, key, url, block_off, block_len, off, len) VALUES (?,?,?,?,?,?,?)",
            [(t, k, u, off, len(comp), o, n) for t, k, u, o, n in self._pending],
        )
        self.db.commit()
        self._block, self._pending, self._block_size = [], [], 0
        self._keys.clear()  # already in SQLite's unique index

    def close(self) -> dict:
        self._flush()
        self.db.execute("CREATE INDEX IF NOT EXISTS pages_url ON pages(url)")
        self.db.commit()
        self.db.close()
        self.data.close()
        return {"articles": self.count, "duplicates": self.duplicates}


class PageStore:
    """Read-only article store, safe to share between threads and processes."""

    def __init__(self, directory: Path) -> None:
        self.dir = Path(directory)
        data, index = self.dir / DATA_FILE, self.dir / INDEX_FILE
        for path in (data, index):
            if not path.is_file():
                raise FileNotFoundError(f"article store {self.dir} is incomplete: {path.name} is missing")
        self._data_path = data
        self._fd = os.open(data, os.O_RDONLY)
        self._local = threading.local()
        self.count = int(self._conn().execute("SELECT count(*) FROM pages").fetchone()[0])

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(f"file:{self.dir / INDEX_FILE}?mode=ro&immutable=1", uri=True, check_same_thread=False)
            self._local.conn = conn
        return conn

    def __len__(self) -> int:
        return self.count

    def _read(self, row: tuple) -> Article:
        title, url, block_off, block_len, off, n = row
        block = zlib.decompress(os.pread(self._fd, block_len, block_off))
        return Article(title=title, url=url, text=block[off : off + n].decode("utf-8"))

    def get(self, title_or_url: str) -> Article | None:
        """An article by exact title (case/accents/underscores ignored) or URL; None if absent."""
        if not isinstance(title_or_url, str) or not title_or_url.strip():
            return None
        cols = "title, url, block_off, block_len, off, len"
        conn = self._conn()
        row = conn.execute(f"SELECT {cols} FROM pages WHERE key=?", (title_key(title_or_url),)).fetchone()
        if row is None:
            row = conn.execute(f"SELECT {cols} FROM pages WHERE url=?", (title_or_url.strip(),)).fetchone()
        return self._read(row) if row else None

    def suggest(self, title: str, limit: int = 5) -> list[str]:
        """Titles that start like the given one (for 'did you mean' messages)."""
        key = title_key(title)[:12]
        if not key:
            return []
        rows = self._conn().execute(
            "SELECT title FROM pages WHERE key >= ? AND key < ? ORDER BY key LIMIT ?", (key, key + "\uffff", limit)
        )
        return [r[0] for r in rows]

    def titles(self) -> Iterator[str]:
        for (t,) in self._conn().execute("SELECT title FROM pages ORDER BY id"):
            yield t

    def close(self) -> None:
        os.close(self._fd)


def read_article_jsonl(path: Path) -> Iterator[dict]:
    """Stream {url, title, text} objects from a JSONL (optionally .gz) file."""
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "rt", encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            line = line.strip()
            if not line:
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{path}:{lineno}: not a JSON object ({exc.msg})") from None
            if not isinstance(obj, dict) or not isinstance(obj.get("title"), str) or not isinstance(obj.get("text"), str):
                raise ValueError(f"{path}:{lineno}: expected an object with string 'title' and 'text' (and 'url')")
            yield obj


def article_passages(article: dict, source: str, words_per_passage: int = 200,
                     provenance: dict | None = None, dataset_name: str = "") -> Iterator[dict]:
    """Split an article into passages of about `words_per_passage` words on paragraph breaks.

    Passage titles are ``"<article title> § <n>"`` so `browse_article` finds the article from
    any hit; doc ids are ``"<source>:<url or title>#<n>"``.
    """
    title = article["title"].strip()
    ident = (article.get("url") or title).strip()
    paras = [p.strip() for p in article["text"].split("\n") if p.strip()]
    chunk: list[str] = []
    n_words = 0
    part = 0

    def emit() -> dict:
        nonlocal part
        part += 1
        return {
            "doc_id": f"{source}:{ident}#{part}",
            "source": source,
            "title": f"{title} § {part}" if part > 1 else title,
            "content": "\n".join(chunk),
            "category": "article",
            "dataset_name": dataset_name or source,
            "provenance": provenance,
        }

    for para in paras:
        words = para.split()
        while len(words) > words_per_passage * 2:  # very long paragraph: hard split
            if chunk:
                yield emit()
                chunk, n_words = [], 0
            chunk = [" ".join(words[:words_per_passage])]
            yield emit()
            chunk, words = [], words[words_per_passage:]
        chunk.append(" ".join(words))
        n_words += len(words)
        if n_words >= words_per_passage:
            yield emit()
            chunk, n_words = [], 0
    if chunk:
        yield emit()


def build_page_store(articles: Iterable[dict], directory: Path) -> dict:
    writer = PageStoreWriter(directory)
    for art in articles:
        writer.add(art["title"], art["text"], art.get("url", ""))
    return writer.close()
