"""`KnowledgeBase`: open a built knowledge base, search it, get passages and articles.

A knowledge base is a directory written by `kb_service.ingest.build_kb`:

    manifest.json        counts per source, engine settings, provenance, build inputs
    passages.sqlite      the passages (SQLite, read-only + immutable once published)
    bm25/                bm25s index (CSC matrix, memory-mapped), or shards of it (shards.json)
    tantivy/             tantivy index (positions; used for phrase/boolean queries)
    docmeta/             per-document source and category ids (numpy, memory-mapped)
    articles/            optional article store (pages.zlib + pages.sqlite)

`KnowledgeBase.open()` validates all of it and raises `KBNotBuiltError` / `KBCorruptError`
naming the path and the command that builds it. It never degrades to empty results.
"""

from __future__ import annotations

import json
import numbers
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Iterable

import numpy as np

from kb_service.analysis import MAX_QUERY_TERMS, Highlighter, plan_query
from kb_service.schema import Passage
from kb_service.store import check_text

FORMAT = "hcgym-kb"
FORMAT_VERSION = 1
MAX_K = 1000


def check_k(k: object) -> int:
    """The number of passages asked for, as an int in [0, MAX_K].

    Raises:
        TypeError: `k` is not an integer (booleans and floats, infinity included, are refused).
        ValueError: `k` is negative or above MAX_K.
    """
    if isinstance(k, bool) or not isinstance(k, numbers.Integral):
        raise TypeError(f"k must be an integer number of passages (0-{MAX_K}), got {type(k).__name__} {k!r:.40}")
    if not 0 <= k <= MAX_K:
        raise ValueError(f"k must be between 0 and {MAX_K}, got {k}")
    return int(k)


class KBError(RuntimeError):
    """The knowledge base cannot be used."""


class KBNotBuiltError(KBError):
    """No knowledge base at the path (or an empty one)."""


class KBCorruptError(KBError):
    """A knowledge base is present but unreadable or inconsistent."""


class UnknownSourceError(ValueError):
    """A `source` filter names no source of this knowledge base."""


class UnknownDocError(KeyError):
    """No passage has this doc_id."""

    def __str__(self) -> str:  # KeyError quotes its argument; keep the message readable
        return str(self.args[0]) if self.args else "unknown doc_id"


class ArticleNotFoundError(KeyError):
    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "article not found"


def default_kb_path() -> Path:
    from envs.core.paths import data_dir

    return data_dir() / "kb"


def build_command(path: Path) -> str:
    """How to build the KB at `path`, as shown in error messages."""
    try:
        if Path(path).resolve() == default_kb_path().resolve():
            return "`hcgym data build` (or `hcgym kb build --default`)"
    except OSError:
        pass
    return f"`hcgym kb build PASSAGE_FILES... --out {path}`"


def _fail(cls: type[KBError], path: Path, problem: str) -> KBError:
    return cls(f"knowledge base at {path} {problem}. Build it with {build_command(path)}.")


class KnowledgeBase:
    """Read-only access to a built knowledge base; safe across threads and processes."""

    def __init__(self, path: Path, manifest: dict, store, bm25, tantivy_searcher, source_ids, category_ids,
                 sources: list[str], categories: list[str], articles=None) -> None:
        self.path = path
        self.manifest = manifest
        self.store = store
        self.bm25 = bm25
        self.tantivy = tantivy_searcher
        self._source_ids = source_ids
        self._category_ids = category_ids
        self.sources = sources
        self._source_index = {s: i for i, s in enumerate(sources)}
        self.categories = categories
        self._category_index = {c: i for i, c in enumerate(categories)}
        self.articles = articles
        self.n_passages = int(manifest["n_passages"])
        self.highlighter = Highlighter()
        self._masks: OrderedDict = OrderedDict()
        self._mask_lock = threading.Lock()

    # ---------------------------------------------------------------------------- opening
    @classmethod
    def open(cls, path: str | Path | None = None, *, warmup: bool = True, bm25=None) -> "KnowledgeBase":
        """Open the KB at `path` (default: the one `hcgym data build` writes). Fails loudly.

        `bm25`: a searcher of this KB's bm25 index opened elsewhere (the KB service's shard actors,
        `kb_service.service`), used instead of opening ``bm25/`` in this process; it is validated
        like the local one.
        """
        path = Path(path) if path is not None else default_kb_path()
        building = path.with_name(path.name + ".building").exists()
        if not path.exists():
            hint = " (a build is in progress or was interrupted; rerun the build to resume it)" if building else ""
            raise _fail(KBNotBuiltError, path, f"does not exist{hint}")
        if not path.is_dir():
            raise _fail(KBCorruptError, path, "is not a directory")
        mpath = path / "manifest.json"
        if not mpath.is_file():
            hint = " (a build is in progress or was interrupted; rerun the build to resume it)" if building else ""
            raise _fail(KBNotBuiltError, path, f"has no manifest.json{hint}")
        try:
            manifest = json.loads(mpath.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise _fail(KBCorruptError, path, f"has an unreadable manifest.json ({exc})") from None
        if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
            raise _fail(KBCorruptError, path, "has a manifest.json that is not a knowledge-base manifest")
        if manifest.get("format_version") != FORMAT_VERSION:
            raise _fail(KBCorruptError, path, f"has format version {manifest.get('format_version')}, "
                                              f"this code reads {FORMAT_VERSION}")
        n = manifest.get("n_passages")
        if not isinstance(n, int) or n <= 0:
            raise _fail(KBNotBuiltError, path, "is empty (0 passages)")
        from kb_service.shards import SHARDS_FILE, is_sharded

        sharded = is_sharded(path / "bm25")
        bm25_files = [f"bm25/{SHARDS_FILE}"] if sharded else [
            "bm25/params.index.json", "bm25/vocab.index.json", "bm25/data.csc.index.npy",
            "bm25/indices.csc.index.npy", "bm25/indptr.csc.index.npy"]
        required = ["passages.sqlite", *bm25_files, "tantivy/meta.json",
                    "docmeta/source_ids.npy", "docmeta/category_ids.npy", "docmeta/names.json"]
        missing = [r for r in required if not (path / r).is_file()]
        if missing:
            raise _fail(KBCorruptError, path, f"is incomplete: missing {', '.join(missing)}")

        from kb_service.engines import BM25Searcher, TantivySearcher
        from kb_service.store import StoreReader

        try:
            store = StoreReader(path / "passages.sqlite")
            rows = store.max_rowid()
        except Exception as exc:  # sqlite3.DatabaseError and friends
            raise _fail(KBCorruptError, path, f"has an unreadable passages.sqlite ({type(exc).__name__}: {exc})") from None
        if rows != n:
            raise _fail(KBCorruptError, path, f"has {rows} passages in passages.sqlite but the manifest says {n}")
        try:
            if bm25 is not None:
                pass
            elif sharded:
                from kb_service.shards import ShardedBM25Searcher

                bm25 = ShardedBM25Searcher(path / "bm25")
            else:
                bm25 = BM25Searcher(path / "bm25")
            bm25.validate()
        except Exception as exc:
            raise _fail(KBCorruptError, path, f"has an unreadable bm25 index ({type(exc).__name__}: {exc})") from None
        if bm25.num_docs != n:
            raise _fail(KBCorruptError, path, f"has a bm25 index of {bm25.num_docs} documents, expected {n}")
        try:
            tv = TantivySearcher(path / "tantivy")
        except Exception as exc:
            raise _fail(KBCorruptError, path, f"has an unreadable tantivy index ({type(exc).__name__}: {exc})") from None
        if tv.num_docs != n:
            raise _fail(KBCorruptError, path, f"has a tantivy index of {tv.num_docs} documents, expected {n}")
        try:
            source_ids = np.load(path / "docmeta/source_ids.npy", mmap_mode="r")
            category_ids = np.load(path / "docmeta/category_ids.npy", mmap_mode="r")
            names = json.loads((path / "docmeta/names.json").read_text(encoding="utf-8"))
            sources, categories = list(names["sources"]), list(names["categories"])
        except Exception as exc:
            raise _fail(KBCorruptError, path, f"has unreadable docmeta ({type(exc).__name__}: {exc})") from None
        if len(source_ids) != n or len(category_ids) != n:
            raise _fail(KBCorruptError, path, "has docmeta arrays of the wrong length")
        articles = None
        if (path / "articles").is_dir():
            from kb_service.pages import PageStore

            try:
                articles = PageStore(path / "articles")
            except Exception as exc:
                raise _fail(KBCorruptError, path, f"has an unreadable article store ({exc})") from None
        kb = cls(path, manifest, store, bm25, tv, source_ids, category_ids, sources, categories, articles)
        if warmup:
            bm25.warmup()
        return kb

    # ---------------------------------------------------------------------------- search
    def _normalise_sources(self, source: str | Iterable[str] | None) -> list[str] | None:
        if source is None:
            return None
        if isinstance(source, str):
            wanted = [source]
        elif isinstance(source, (list, tuple, set, frozenset)):
            wanted = list(source)
            for position, item in enumerate(wanted):
                if not isinstance(item, str):
                    raise TypeError(f"source[{position}] must be a source name (str), got {type(item).__name__}")
        else:
            raise TypeError(f"source must be a source name or a list of them, got {type(source).__name__}")
        wanted = [s.strip() for s in wanted if s and s.strip()]
        if not wanted:
            return None
        unknown = [s for s in wanted if s not in self._source_index]
        if unknown:
            raise UnknownSourceError(
                f"unknown source {', '.join(repr(u) for u in unknown)}; this knowledge base has: {', '.join(self.sources)}"
            )
        return list(dict.fromkeys(wanted))

    def _mask(self, sources: list[str] | None, category: str | None) -> np.ndarray | None:
        if sources is None and category is None:
            return None
        key = (tuple(sources) if sources else None, category)
        with self._mask_lock:
            mask = self._masks.get(key)
            if mask is not None:
                self._masks.move_to_end(key)
                return mask
        keep = np.ones(self.n_passages, dtype=bool)
        if sources:
            keep &= np.isin(self._source_ids, [self._source_index[s] for s in sources])
        if category is not None:
            keep &= self._category_ids == self._category_index[category]
        mask = keep.astype(np.float32)
        with self._mask_lock:
            self._masks[key] = mask
            while len(self._masks) > 16:
                self._masks.popitem(last=False)
        return mask

    def search(self, query: str, k: int = 10, source: str | Iterable[str] | None = None,
               category: str | None = None) -> list[Passage]:
        """BM25-ranked passages for any text, best first (an empty list when nothing matches).

        Args:
            query: Free text (an OR of its words), or query syntax: "a phrase", AND, OR, NOT,
                +required, -excluded, parentheses.
            k: Number of passages, an integer from 0 to 1000 (TypeError / ValueError otherwise).
            source: Restrict to one source name or a list of them.
            category: Restrict to one category.
        """
        docs, scores, terms = self._rank(query, k, source, category)
        return self._passages(docs, scores, terms) if docs else []

    def rank(self, query: str, k: int = 10, source: str | Iterable[str] | None = None,
             category: str | None = None) -> list[tuple[int, float]]:
        """Ranking only: (document number, BM25 score) best first, without fetching passages.

        Document number ``i`` is the passage in SQLite row ``i + 1``; `search` is `rank` plus
        fetching those rows and building snippets.
        """
        docs, scores, _terms = self._rank(query, k, source, category)
        return list(zip(docs, scores))

    def _rank(self, query, k, source, category) -> tuple[list[int], list[float], set[str]]:
        k = check_k(k)
        sources = self._normalise_sources(source)
        if category is not None and not isinstance(category, str):
            raise TypeError(f"category must be a category name (str) or None, got {type(category).__name__}")
        if k == 0 or (category is not None and category not in self._category_index):
            return [], [], set()
        plan = plan_query(query)
        if plan.kind == "empty":
            return [], [], set()
        if plan.kind == "free":
            ids = self.bm25.term_ids(plan.terms, MAX_QUERY_TERMS)
            if not ids:
                return [], [], set()
            docs, scores = self.bm25.search(ids, k, self._mask(sources, category))
            return docs.tolist(), scores.tolist(), plan.highlight
        q = self.tantivy.to_query(plan.tree, sources, category)
        docs, scores = self.tantivy.search(q, k)
        return docs, scores, plan.highlight

    def _passages(self, docs: list[int], scores: list[float], terms: set[str]) -> list[Passage]:
        rows = self.store.rows_by_index(docs)
        out: list[Passage] = []
        for d, s in zip(docs, scores):
            row = rows.get(d)
            if row is None:  # cannot happen with a validated KB; never hide it
                raise KBCorruptError(f"knowledge base at {self.path}: document {d} is in the index but not in the store")
            _, doc_id, source, title, content, category, dataset_name, prov_id = row
            out.append(Passage(doc_id, source, title, self.highlighter.snippet(content, terms), float(s), category,
                               dataset_name, None, self.store.provenance.get(prov_id)))
        return out

    # ---------------------------------------------------------------------------- lookups
    def get(self, doc_id: str) -> Passage:
        """The full passage with this doc_id.

        Raises:
            UnknownDocError: no passage has it.
            TypeError / ValueError: naming `doc_id` when it is not a str (an int is read as its digits)
                or holds a lone surrogate.
        """
        if isinstance(doc_id, int) and not isinstance(doc_id, bool):
            doc_id = str(doc_id)
        row = self.store.row_by_doc_id(check_text("doc_id", doc_id))
        if row is None:
            raise UnknownDocError(f"no passage with doc_id {str(doc_id)[:200]!r} in the knowledge base at {self.path}")
        _, did, source, title, content, category, dataset_name, prov_id = row
        return Passage(doc_id=did, source=source, title=title, category=category, dataset_name=dataset_name,
                       snippet=content[:300], content=content, provenance=self.store.provenance.get(prov_id))

    def article(self, title_or_url: str):
        """A full article from the article store, by title, URL or a passage title "T § n"."""
        if self.articles is None:
            raise ArticleNotFoundError(
                f"the knowledge base at {self.path} has no article store; add one with "
                f"`hcgym kb build --articles ARTICLES.jsonl --out {self.path}`"
            )
        text = check_text("title_or_url", "" if title_or_url is None else title_or_url).strip()
        art = self.articles.get(text)
        if art is None and " § " in text:
            art = self.articles.get(text.split(" § ")[0])
        if art is None:
            near = self.articles.suggest(text)
            hint = f" Titles starting alike: {'; '.join(near)}." if near else ""
            raise ArticleNotFoundError(f"no article titled {text[:200]!r}.{hint}")
        return art

    def stats(self) -> dict:
        m = self.manifest
        return {
            "path": str(self.path),
            "n_passages": self.n_passages,
            "sources": m.get("sources", {}),
            "n_categories": len(self.categories),
            "articles": len(self.articles) if self.articles is not None else 0,
            "engine": m.get("engine", {}),
            "built_at": m.get("built_at"),
            "provenance": m.get("provenance", {}),
        }

    def close(self) -> None:
        self.store.close()
        if self.articles is not None:
            self.articles.close()


_OPEN: dict[str, KnowledgeBase] = {}
_OPEN_LOCK = threading.Lock()


def open_shared(path: str | Path | None = None) -> KnowledgeBase:
    """One KnowledgeBase per path per process (the embedded default for env tools)."""
    key = str(Path(path) if path is not None else default_kb_path())
    with _OPEN_LOCK:
        kb = _OPEN.get(key)
        if kb is None:
            kb = _OPEN[key] = KnowledgeBase.open(key)
        return kb
