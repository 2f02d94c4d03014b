"""Building a knowledge base: stream passages in, deduplicate, index, publish atomically.

Inputs are streamed record by record (constant memory): JSONL (``.jsonl``/``.ndjson``/``.json``,
optionally ``.gz``), Parquet (read in row batches), a SQLite FTS5 database in the paper's
reference layout (``passages_fts(doc_id, source, title, content, category, dataset_name)``),
article JSONL (``{url, title, text}``, which also fills the article store), or any Python
iterator of dicts (the default build's sources).

Stages, all in ``<out>.building/`` next to the target:

1. ingest: rows go into ``passages.sqlite`` with ``INSERT OR IGNORE`` on the unique doc_id (the
   first occurrence of a doc_id wins; later ones are counted as duplicates). After every batch
   the input's position is committed in the same transaction, so an interrupted build resumes
   where it stopped (``resume=True``, the default); an input whose file changed since starts
   the build afresh.
2. index: one pass over the store in row order feeds the bm25s builder and the tantivy writer
   with the same analysed text; per-document source/category ids are written for filters.
3. publish: ``manifest.json`` is written last, then the directory is swapped into place, so a
   reader sees either the old knowledge base or the new one, never a half-built one.
"""

from __future__ import annotations

import gzip
import json
import os
import shutil
import sqlite3
import time
from array import array
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from envs.core.files import as_disk_full
from kb_service.kb import FORMAT, FORMAT_VERSION
from kb_service.schema import IngestError
from kb_service.store import indexed_text

REFERENCE_TABLE = "passages_fts"
REFERENCE_COLUMNS = ("doc_id", "source", "title", "content", "category", "dataset_name")


@dataclass
class Input:
    """One stream of passage records. `open(skip)` yields records after the first `skip`."""

    name: str
    fingerprint: str
    open: Callable[[int], Iterator[Any]]
    total: int | None = None
    provenance: dict | None = None
    articles: bool = False  # records are {url, title, text} articles, split into passages


# ------------------------------------------------------------------------------------ readers


def _jsonl_records(path: Path, skip: int) -> Iterator[Any]:
    opener = gzip.open if path.name.endswith(".gz") else open
    seen = 0
    with opener(path, "rt", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip():
                continue
            seen += 1
            if seen <= skip:
                continue
            try:
                yield json.loads(line)
            except json.JSONDecodeError as exc:
                yield _Bad(f"line {lineno}: invalid JSON ({exc.msg})")


def _parquet_records(path: Path, skip: int) -> Iterator[Any]:
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(path)
    names = set(pf.schema_arrow.names)
    if "content" not in names and "text" not in names:
        raise IngestError(f"{path}: a Parquet passage file needs a 'content' column (has: {sorted(names)})")
    wanted = [c for c in (*REFERENCE_COLUMNS, "id", "text", "provenance") if c in names]
    seen = 0
    for batch in pf.iter_batches(batch_size=4096, columns=wanted):
        n = batch.num_rows
        if seen + n <= skip:
            seen += n
            continue
        start = max(0, skip - seen)
        seen += n
        yield from batch.slice(start).to_pylist()


def _fts5_records(path: Path, skip: int) -> Iterator[Any]:
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        cols = _reference_columns(conn, path)
        sel = ", ".join(cols)
        cur = conn.execute(f"SELECT {sel} FROM {REFERENCE_TABLE} ORDER BY rowid LIMIT -1 OFFSET ?", (skip,))
        while True:
            rows = cur.fetchmany(2000)
            if not rows:
                break
            for row in rows:
                yield dict(zip(cols, row))
    finally:
        conn.close()


def _reference_columns(conn: sqlite3.Connection, path: Path) -> list[str]:
    try:
        info = conn.execute(f"PRAGMA table_info({REFERENCE_TABLE})").fetchall()
    except sqlite3.DatabaseError as exc:
        raise IngestError(f"{path}: not a readable SQLite database ({exc})") from None
    cols = [r[1] for r in info]
    if not cols:
        raise IngestError(f"{path}: no table {REFERENCE_TABLE!r}; expected the reference layout "
                          f"{REFERENCE_TABLE}({', '.join(REFERENCE_COLUMNS)})")
    missing = [c for c in ("doc_id", "content") if c not in cols]
    if missing:
        raise IngestError(f"{path}: table {REFERENCE_TABLE} lacks column(s) {missing}; expected "
                          f"{REFERENCE_TABLE}({', '.join(REFERENCE_COLUMNS)})")
    return [c for c in REFERENCE_COLUMNS if c in cols]


def _fingerprint(path: Path) -> str:
    st = path.stat()
    return f"file:{st.st_size}:{st.st_mtime_ns}"


def file_input(path: str | Path, *, provenance: dict | None = None, articles: bool = False,
               source: str = "wikipedia") -> Input:
    """An Input for a passage file (JSONL, Parquet, reference FTS5 SQLite) or an article JSONL."""
    path = Path(path)
    if not path.is_file():
        raise IngestError(f"input file {path} does not exist")
    name = path.name.lower()
    if articles:
        from kb_service.pages import article_passages, read_article_jsonl

        def open_articles(skip: int) -> Iterator[Any]:
            seen = 0
            for art in read_article_jsonl(path):
                for rec in article_passages(art, source=source, provenance=provenance):
                    seen += 1
                    if seen > skip:
                        yield rec

        return Input(f"articles:{path.resolve()}", _fingerprint(path), open_articles, provenance=provenance,
                     articles=True)
    if name.endswith((".jsonl", ".ndjson", ".json", ".jsonl.gz", ".ndjson.gz", ".json.gz")):
        opener = lambda skip: _jsonl_records(path, skip)  # noqa: E731
        total = None
    elif name.endswith((".parquet", ".pq")):
        import pyarrow.parquet as pq

        total = pq.ParquetFile(path).metadata.num_rows
        opener = lambda skip: _parquet_records(path, skip)  # noqa: E731
    elif name.endswith((".db", ".sqlite", ".sqlite3")):
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            _reference_columns(conn, path)
            total = int(conn.execute(f"SELECT count(*) FROM {REFERENCE_TABLE}").fetchone()[0])
        finally:
            conn.close()
        opener = lambda skip: _fts5_records(path, skip)  # noqa: E731
    else:
        raise IngestError(f"{path}: unknown input format; use .jsonl/.ndjson/.json(.gz), .parquet, or a "
                          f"reference FTS5 database (.db/.sqlite)")
    return Input(str(path.resolve()), _fingerprint(path), opener, total=total, provenance=provenance)


def iterable_input(name: str, fingerprint: str, factory: Callable[[], Iterable[Any]],
                   provenance: dict | None = None, total: int | None = None) -> Input:
    """An Input over a re-creatable iterator (`factory()` is called again on resume)."""

    def opener(skip: int) -> Iterator[Any]:
        for i, rec in enumerate(factory()):
            if i >= skip:
                yield rec

    return Input(name, fingerprint, opener, total=total, provenance=provenance)


# ------------------------------------------------------------------------------------ records


class _Bad:
    def __init__(self, reason: str) -> None:
        self.reason = reason


def _text(value: Any) -> str:
    if value is None:
        return ""
    return value if isinstance(value, str) else str(value)


def coerce_record(rec: Any) -> tuple[tuple[str, str, str, str, str, str], dict | None] | str:
    """(doc_id, source, title, content, category, dataset_name), provenance -- or a reason string."""
    if isinstance(rec, _Bad):
        return rec.reason
    if not isinstance(rec, dict):
        return f"not an object ({type(rec).__name__})"
    doc_id = _text(rec.get("doc_id", rec.get("id"))).strip()
    if not doc_id:
        return "missing doc_id"
    source = _text(rec.get("source")).strip()
    if not source:
        return f"{doc_id}: missing source"
    content = _text(rec.get("content", rec.get("text")))
    if not content.strip():
        return f"{doc_id}: empty content"
    prov = rec.get("provenance")
    if isinstance(prov, str):
        try:
            prov = json.loads(prov)
        except json.JSONDecodeError:
            prov = {"note": prov}
    prov = {str(k): _text(v) for k, v in prov.items()} if isinstance(prov, dict) and prov else None
    row = (doc_id[:512], source[:128], _text(rec.get("title")).strip(), content,
           _text(rec.get("category")).strip(), _text(rec.get("dataset_name")).strip())
    return row, prov


# ------------------------------------------------------------------------------------ build


@dataclass
class BuildReport:
    out: str
    n_passages: int = 0
    sources: dict[str, int] = field(default_factory=dict)
    inputs: list[dict] = field(default_factory=list)
    articles: int = 0
    seconds: dict[str, float] = field(default_factory=dict)
    bm25_shards: dict | None = None

    def as_dict(self) -> dict:
        out = {"out": self.out, "n_passages": self.n_passages, "sources": self.sources, "inputs": self.inputs,
               "articles": self.articles, "seconds": self.seconds}
        if self.bm25_shards is not None:
            out["bm25_shards"] = self.bm25_shards
        return out


def _tqdm(enabled: bool, **kw):
    from tqdm import tqdm

    return tqdm(disable=not enabled, mininterval=1.0, **kw)


def build_kb(inputs: list[Input], out: str | Path, *, article_files: list[Path] | None = None,
             article_iter: Callable[[], Iterable[dict]] | None = None, resume: bool = True,
             progress: bool = True, batch_size: int = 2000, manifest_extra: dict | None = None,
             echo: Callable[[str], None] = print, shard_docs: int | None = None,
             memory_budget_mb: int | None = None, workers: int | None = None) -> dict:
    """Build (or resume building) a knowledge base at `out`; returns the summary dict.

    The build runs in `OUT.building/` and replaces `out` only when complete.

    `shard_docs` / `memory_budget_mb`: build the bm25 index as shards (`kb_service.shards`) of at
    most `shard_docs` passages (default `DEFAULT_SHARD_DOCS`), each cut small enough that the
    build process's peak RSS stays under `memory_budget_mb` (interpreter and libraries
    included); the index stage then commits shard by shard (and tantivy in eighths), so an
    interrupted build resumes after the last commit. None of either: one index built in memory.

    `workers`: processes that analyse and weigh the bm25 shards of the sharded build
    (`kb_service.parallel_build`; the same index bit for bit). Default: the machine's cores (at
    most one per `PASSAGES_PER_AUTO_WORKER` passages), fewer when `memory_budget_mb` cannot give each
    its share (the budget less what this process holds,
    split equally; a worker's own interpreter counts in its share). 1: all in this process.

    Raises:
        ValueError: naming `shard_docs` / `memory_budget_mb` / `workers` when not a positive integer,
            the budget when it is below what the process already holds plus a minimal working set
            (or, naming both, too small for `workers` workers), `workers` > 1 for the in-memory build.
        DiskFullError: naming the staging folder when the disk fills; the passages committed so far
            stay there and a rerun (resume=True) continues after them.
    """
    for name, value in (("shard_docs", shard_docs), ("memory_budget_mb", memory_budget_mb), ("workers", workers)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ValueError(f"{name} must be a positive integer or None, got {value!r}")
    if workers is not None and workers > 1 and shard_docs is None and memory_budget_mb is None:
        raise ValueError(f"workers={workers} applies to the sharded build: give shard_docs or memory_budget_mb too "
                         f"(the in-memory build is one process)")
    staging = Path(out).parent / (Path(out).name + ".building")
    try:
        return _build_kb(inputs, out, article_files=article_files, article_iter=article_iter, resume=resume,
                         progress=progress, batch_size=batch_size, manifest_extra=manifest_extra, echo=echo,
                         shard_docs=shard_docs, memory_budget_mb=memory_budget_mb, workers=workers)
    except Exception as exc:
        full = as_disk_full(exc, staging)
        if full is None or (full is exc and full.hint):
            raise
        raise full.with_hint(f"The knowledge base at {out} is unchanged; {staging} keeps the "
                             f"{_committed_passages(staging)} passages committed so far. Free space and run the "
                             f"build again (without forcing a fresh start): it resumes after them") from exc


def _committed_passages(staging: Path) -> int:
    """Passages the staging store holds (its committed transactions); 0 when it cannot be read."""
    try:
        conn = sqlite3.connect(f"file:{staging / 'passages.sqlite'}?mode=ro", uri=True)
        try:
            return int(conn.execute("SELECT count(*) FROM passages").fetchone()[0])
        finally:
            conn.close()
    except sqlite3.Error:
        return 0


def _build_kb(inputs: list[Input], out: str | Path, *, article_files: list[Path] | None, article_iter,
              resume: bool, progress: bool, batch_size: int, manifest_extra: dict | None,
              echo: Callable[[str], None], shard_docs: int | None, memory_budget_mb: int | None,
              workers: int | None) -> dict:
    out = Path(out)
    staging = out.parent / (out.name + ".building")
    t0 = time.perf_counter()
    if memory_budget_mb is not None:  # fail before touching anything when the budget cannot work at all
        _memory_plan(memory_budget_mb, lambda _s: None, workers)
    if staging.exists() and not resume:
        shutil.rmtree(staging)
    staging.mkdir(parents=True, exist_ok=True)
    report = BuildReport(out=str(out))

    from kb_service.store import StoreWriter

    writer = StoreWriter(staging / "passages.sqlite")
    try:
        for inp in inputs:
            prog = writer.progress(inp.name)
            if prog and prog["fingerprint"] != inp.fingerprint:
                writer.close()
                echo(f"[kb] input {inp.name} changed since the interrupted build; starting the build afresh")
                return build_kb(inputs, out, article_files=article_files, article_iter=article_iter, resume=False,
                                progress=progress, batch_size=batch_size, manifest_extra=manifest_extra, echo=echo,
                                shard_docs=shard_docs, memory_budget_mb=memory_budget_mb, workers=workers)
            report.inputs.append(_ingest_one(writer, inp, prog, progress, batch_size, echo))
        report.seconds["ingest"] = round(time.perf_counter() - t0, 1)
        n = writer.count()
        echo(f"[kb] ingest done: {n:,} passages from {len(inputs)} input(s) in {report.seconds['ingest']:.0f}s; "
             f"the inputs are no longer read")
        if n == 0:
            rejected = sum(i["rejected"] for i in report.inputs)
            raise IngestError(f"no passages to index: the inputs gave 0 valid records ({rejected} rejected)"
                              + (f"; first problems: {report.inputs[0].get('problems')}" if report.inputs else ""))
        writer.finalize()

        t1 = time.perf_counter()
        n_articles = 0
        if article_files or article_iter is not None:
            from kb_service.pages import PageStoreWriter, read_article_jsonl

            pw = PageStoreWriter(staging / "articles")
            streams: list[Iterable[dict]] = [read_article_jsonl(Path(p)) for p in (article_files or [])]
            if article_iter is not None:
                streams.append(article_iter())
            for stream in streams:
                for art in stream:
                    pw.add(art["title"], art["text"], art.get("url", ""))
            n_articles = pw.close()["articles"]
            report.seconds["articles"] = round(time.perf_counter() - t1, 1)

        t2 = time.perf_counter()
        if shard_docs is None and memory_budget_mb is None:
            index_info = _build_indexes(writer, staging, n, progress, echo)
        else:
            index_info = _build_indexes_sharded(writer, staging, n, progress, echo, shard_docs, memory_budget_mb,
                                                workers)
        report.seconds["index"] = round(time.perf_counter() - t2, 1)
        report.bm25_shards = index_info.get("bm25_shards")
        report.sources = writer.source_counts()
        provenance = _provenance_by_source(writer)
    finally:
        writer.close()

    report.n_passages = n
    report.articles = n_articles
    report.seconds["total"] = round(time.perf_counter() - t0, 1)
    from importlib.metadata import version

    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "n_passages": n,
        "sources": report.sources,
        "articles": n_articles,
        "provenance": provenance,
        "engine": {"free_text": f"bm25s {version('bm25s')} (numba)", "structured": f"tantivy {version('tantivy')}",
                   "bm25": {"k1": 1.2, "b": 0.75, "idf": "lucene"},
                   "analyzer": "simple tokenizer, remove >40 chars, lowercase, ascii fold, English stop words, "
                               "Snowball English stemmer", **index_info},
        "inputs": report.inputs,
        "built_at": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "build_seconds": report.seconds,
        **(manifest_extra or {}),
    }
    from kb_service.engines import write_json

    write_json(staging / "manifest.json", manifest)
    _publish(staging, out)
    _print_summary(report, echo)
    return report.as_dict()


def _ingest_one(writer, inp: Input, prog: dict | None, progress: bool, batch_size: int, echo) -> dict:
    stats = {"input": inp.name, "rows": 0, "inserted": 0, "duplicates": 0, "rejected": 0, "problems": []}
    if prog and prog["done"]:
        stats.update(rows=prog["rows_done"], inserted=prog["inserted"], duplicates=prog["duplicates"],
                     rejected=prog["rejected"], resumed="already complete")
        echo(f"[kb] {inp.name}: already ingested ({prog['inserted']} passages), skipping")
        return stats
    start = prog["rows_done"] if prog else 0
    if start:
        stats.update(inserted=prog["inserted"], duplicates=prog["duplicates"], rejected=prog["rejected"])
        stats["resumed_from"] = start
        echo(f"[kb] {inp.name}: resuming after {start} records")
    rows_done = start
    batch: list[tuple] = []
    bar = _tqdm(progress, total=inp.total, initial=start, unit=" passages", desc=f"ingest {Path(inp.name).name[:40]}")

    def flush(done: bool) -> None:
        nonlocal batch
        inserted = writer.insert_many(batch) if batch else 0
        stats["inserted"] += inserted
        stats["duplicates"] += len(batch) - inserted
        writer.set_progress(inp.name, inp.fingerprint, rows_done, done, stats["inserted"], stats["duplicates"],
                            stats["rejected"])
        writer.commit()
        bar.update(len(batch))
        batch = []

    for rec in inp.open(start):
        rows_done += 1
        got = coerce_record(rec)
        if isinstance(got, str):
            stats["rejected"] += 1
            if len(stats["problems"]) < 5:
                stats["problems"].append(got)
            continue
        row, prov = got
        batch.append((*row, writer.provenance_id(prov or inp.provenance)))
        if len(batch) >= batch_size:
            flush(False)
    flush(True)
    bar.close()
    stats["rows"] = rows_done
    if not stats["problems"]:
        del stats["problems"]
    return stats


def _build_indexes(writer, staging: Path, n: int, progress: bool, echo) -> dict:
    from kb_service.analysis import analyze
    from kb_service.engines import BM25Builder, TantivyBuilder, write_json

    for sub in ("bm25", "tantivy", "docmeta"):
        if (staging / sub).exists():
            shutil.rmtree(staging / sub)
    # Two passes over the store rather than one: tantivy indexes in background threads, and on
    # 2 cores those threads and the Python thread feeding bm25s slow each other down (docs/benchmarks.md,
    # "Figures behind code defaults").
    bm = BM25Builder()
    sources: dict[str, int] = {}
    categories: dict[str, int] = {}
    source_ids = np.zeros(n, dtype=np.int16)
    category_ids = np.zeros(n, dtype=np.int32)
    bar = _tqdm(progress, total=n, unit=" passages", desc="index bm25s")
    for rows in writer.iter_rows():
        for rowid, _doc_id, source, title, content, category, _ds, _prov in rows:
            i = rowid - 1
            bm.add(analyze(indexed_text(title, content)))
            source_ids[i] = sources.setdefault(source, len(sources))
            category_ids[i] = categories.setdefault(category, len(categories))
        bar.update(len(rows))
    bar.close()
    if len(sources) > np.iinfo(np.int16).max:
        raise IngestError(f"too many distinct sources ({len(sources)}); sources name collections, not documents")
    t = time.perf_counter()
    info = bm.save(staging / "bm25")
    del bm
    t_bm = time.perf_counter() - t
    tv = TantivyBuilder(staging / "tantivy")
    bar = _tqdm(progress, total=n, unit=" passages", desc="index tantivy")
    for rows in writer.iter_rows():
        for rowid, _doc_id, source, title, content, category, _ds, _prov in rows:
            tv.add(rowid - 1, indexed_text(title, content), source, category)
        bar.update(len(rows))
    bar.close()
    t = time.perf_counter()
    tv.close()
    echo(f"[kb] indexes written ({info['vocab']} terms, {info['postings']} postings; bm25s matrix {t_bm:.1f}s, "
         f"tantivy commit {time.perf_counter() - t:.1f}s)")
    (staging / "docmeta").mkdir(exist_ok=True)
    np.save(staging / "docmeta" / "source_ids.npy", source_ids)
    np.save(staging / "docmeta" / "category_ids.npy", category_ids)
    write_json(staging / "docmeta" / "names.json", {"sources": list(sources), "categories": list(categories)})
    return {"vocabulary": info["vocab"], "postings": info["postings"]}


# Memory the index stage keeps for itself beyond the bm25 shard's working set and tantivy's heap:
# a batch of rows read from the store, the analysed tokens of one passage, the per-shard filter
# ids and allocator slack (measured peaks in docs/benchmarks.md, "KB scaling").
INDEX_HEADROOM_BYTES = 24 << 20
MIN_WORKING_BYTES = 32 << 20
TANTIVY_MIN_HEAP_PER_THREAD = 15_000_000  # tantivy refuses a smaller arena per indexing thread
INDEX_PROGRESS = "index.progress.json"
# The default number of workers gives each at least this many passages: starting one (a fresh
# interpreter importing numpy, bm25s and tantivy) took 0.5-1.1 s on our 2-core machines, what a
# worker takes to index 2,000-4,000 PubMed-length passages into bm25 postings (25,000 in 6.5-7 s).
PASSAGES_PER_AUTO_WORKER = 10_000


def _memory_plan(memory_budget_mb: int | None, echo, workers: int | None = None, max_auto_workers: int | None = None
                 ) -> dict:
    """How the index stage spends a memory budget: the bm25 pass (one shard's working set) and the
    tantivy pass (its indexing heap) run one after the other, each within what the budget leaves
    above the memory this process already holds (measured now, after importing both engines).

    With several bm25 workers (`kb_service.parallel_build`), this process keeps what it holds plus
    `INDEX_HEADROOM_BYTES` and each worker gets an equal share of the rest, its own interpreter
    and libraries included; a worker is assumed to hold about what this process holds (it checks
    its own share once started). `workers` None: the machine's cores, as many as the budget allows,
    at most `max_auto_workers`."""
    from kb_service.parallel_build import machine_cores

    auto = min(machine_cores(), max_auto_workers or machine_cores())
    if memory_budget_mb is None:
        return {"bm25_bytes": None, "tantivy_heap": 256_000_000, "tantivy_threads": None, "batch": 2000,
                "workers": workers or auto, "worker_share": None}
    import tantivy  # noqa: F401  (both engines' libraries count in what the process holds)
    from bm25s.scoring import _select_idf_scorer  # noqa: F401

    from kb_service.shards import process_rss_bytes, release_memory

    release_memory()

    base = process_rss_bytes()
    budget = memory_budget_mb << 20
    free = budget - base - INDEX_HEADROOM_BYTES
    if free < MIN_WORKING_BYTES:
        need = -(-(base + INDEX_HEADROOM_BYTES + MIN_WORKING_BYTES) >> 20)
        raise ValueError(f"memory_budget_mb={memory_budget_mb} is too small: this build process already holds "
                         f"{base >> 20} MB (interpreter, numpy, bm25s, tantivy, SQLite); give at least {need} MB")
    need = base + INDEX_HEADROOM_BYTES + MIN_WORKING_BYTES  # the least share a worker can work in
    fit = max(1, free // need)
    n_workers = min(auto, fit) if workers is None else workers
    if n_workers > fit:
        give = -(-(base + INDEX_HEADROOM_BYTES + n_workers * need) >> 20)
        raise ValueError(f"memory_budget_mb={memory_budget_mb} is too small for workers={n_workers}: each bm25 worker "
                         f"gets an equal share of the budget less what this build process holds ({base >> 20} MB) "
                         f"and {INDEX_HEADROOM_BYTES >> 20} MB of headroom, here {(free // n_workers) >> 20} MB, and "
                         f"needs at least {-(-need >> 20)} MB (its own interpreter and libraries, about what this "
                         f"process holds, plus working memory); give at least {give} MB, or workers={fit}")
    share = free // n_workers  # a worker's share (also when a rerun continues a parallel build on one worker)
    threads = 1 if free < 4 * TANTIVY_MIN_HEAP_PER_THREAD * 2 else 2
    # tantivy's resident memory runs to about twice its heap while it serialises a segment.
    heap = int(min(256_000_000, max(TANTIVY_MIN_HEAP_PER_THREAD * threads + (1 << 20), free // 2)))
    plan = {"bm25_bytes": int(free), "tantivy_heap": heap, "tantivy_threads": threads, "batch": 500,
            "workers": n_workers, "worker_share": share}
    bm25 = (f"bm25 shards cut at ~{free >> 20} MB of working set" if n_workers == 1 else
            f"{n_workers} workers (bm25 units, the tantivy pass) with {share >> 20} MB each (their own "
            f"interpreter included)")
    echo(f"[kb] memory budget {memory_budget_mb} MB: {base >> 20} MB held before indexing; {bm25}, "
         f"tantivy heap {heap >> 20} MB on {threads} thread(s)")
    return plan


def _write_npy_parts(path: Path, parts: list[Path], key: str, dtype, n: int) -> None:
    """Concatenate the `key` arrays of the .npz `parts` into one .npy at `path`, a part at a time."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                                  "shape": (n,)})
        written = 0
        for part in parts:
            with np.load(part) as z:
                arr = z[key].astype(dtype, copy=False)
            fh.write(arr.tobytes())
            written += len(arr)
    if written != n:
        raise IngestError(f"{path}: the index parts hold {written} passages, the store {n}")
    os.replace(tmp, path)


def _build_indexes_sharded(writer, staging: Path, n: int, progress: bool, echo, shard_docs: int | None,
                           memory_budget_mb: int | None, workers: int | None = None) -> dict:
    """`_build_indexes` for a sharded bm25 index in bounded memory, committed as it goes.

    Pass 1 feeds `ShardedBM25Builder` (each shard committed with its passages' source/category
    ids); its `save` weighs the shards with the global statistics. Pass 2 feeds tantivy,
    committing every eighth of the passages. ``index.progress.json`` records what is done, for
    the same number of passages, so a rerun after a kill continues after the last commit of
    the stage it was in. With more than one worker, pass 1, the weighting and the tantivy pass
    run at once in worker processes (`kb_service.parallel_build`); the plan of units is recorded
    in the progress file, so a rerun resumes them whatever its number of workers.
    """
    from kb_service.analysis import analyze
    from kb_service.engines import TantivyBuilder, write_json
    from kb_service.parallel_build import TANTIVY_PROGRESS
    from kb_service.shards import (DEFAULT_SHARD_DOCS, SHARDS_FILE, ShardedBM25Builder, kill_point,
                                   process_rss_bytes, release_memory)

    plan = _memory_plan(memory_budget_mb, echo, workers, max_auto_workers=max(1, n // PASSAGES_PER_AUTO_WORKER))
    context = {"passages": n, "shard_docs": shard_docs, "memory_budget_mb": memory_budget_mb}
    prog_path = staging / INDEX_PROGRESS
    try:
        prog = json.loads(prog_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        prog = None
    if not isinstance(prog, dict) or prog.get("context") != context:
        prog = {"context": context, "bm25": None, "tantivy_rows": 0}
        for sub in ("bm25", "tantivy", "docmeta", "docmeta.parts", "bm25.raw"):
            shutil.rmtree(staging / sub, ignore_errors=True)
        (staging / TANTIVY_PROGRESS).unlink(missing_ok=True)
        write_json(prog_path, prog)

    bm25_dir, parts_dir = staging / "bm25", staging / "docmeta.parts"
    if prog["bm25"] is None:
        names: dict[str, dict[str, int]] = {"sources": {}, "categories": {}}
        pending_src, pending_cat = array("h"), array("i")

        def commit_meta(shard: int, offset: int, num_docs: int) -> None:
            if len(pending_src) != num_docs:
                raise RuntimeError(f"shard {shard}: {len(pending_src)} passages of filter ids for {num_docs} documents")
            part = parts_dir / f"part-{shard:05d}.npz"
            src = np.array(pending_src, dtype=np.int16)
            cat = np.array(pending_cat, dtype=np.int32)
            with open(part.with_suffix(".tmp"), "wb") as fh:
                np.savez(fh, source_ids=src, category_ids=cat,
                         names=np.array(json.dumps({k: list(v) for k, v in names.items()})))
            os.replace(part.with_suffix(".tmp"), part)
            del src, cat, pending_src[:], pending_cat[:]

        builder = ShardedBM25Builder(staging / "bm25.raw", shard_docs or DEFAULT_SHARD_DOCS,
                                     memory_bytes=plan["bm25_bytes"], resume=True, context=context,
                                     on_commit=commit_meta, echo=echo)
        units = prog.get("bm25_units")
        if units is None and plan["workers"] > 1 and builder.committed_shards == 0:
            from kb_service.parallel_build import plan_units

            units = prog["bm25_units"] = plan_units(n, plan["workers"], shard_docs or DEFAULT_SHARD_DOCS)
            write_json(prog_path, prog)
        if units is not None:
            info = _build_parallel(writer, staging, n, builder, units, plan, shard_docs or DEFAULT_SHARD_DOCS,
                                   context, progress, echo)
            prog["bm25"], prog["tantivy_rows"] = info, n  # the workers built the tantivy index too
            write_json(prog_path, prog)
    if prog["bm25"] is None:
        start = builder.n_docs
        if builder.fresh:
            shutil.rmtree(parts_dir, ignore_errors=True)
            shutil.rmtree(bm25_dir, ignore_errors=True)
        else:
            last = parts_dir / f"part-{builder.committed_shards - 1:05d}.npz"
            if builder.committed_shards:
                with np.load(last) as z:
                    saved = json.loads(str(z["names"]))
                names = {k: {name: i for i, name in enumerate(v)} for k, v in saved.items()}
            for stale in parts_dir.glob("part-*"):
                if int(stale.name[5:10]) >= builder.committed_shards:
                    stale.unlink()
            echo(f"[kb] bm25: resuming after {builder.committed_shards} committed shard(s) "
                 f"({start:,} of {n:,} passages indexed)")
        parts_dir.mkdir(parents=True, exist_ok=True)
        sources, categories = names["sources"], names["categories"]
        bar = _tqdm(progress, total=n, initial=start, unit=" passages", desc="index bm25s")
        for rows in writer.iter_rows(batch=plan["batch"], after=start):
            for _rowid, _doc_id, source, title, content, category, _ds, _prov in rows:
                sid = sources.setdefault(source, len(sources))
                if sid > np.iinfo(np.int16).max:
                    raise IngestError(f"too many distinct sources ({len(sources)}); sources name collections, "
                                      f"not documents")
                pending_src.append(sid)
                pending_cat.append(categories.setdefault(category, len(categories)))
                builder.add(analyze(indexed_text(title, content)))
            bar.update(len(rows))
        bar.close()
        if builder.n_docs != n:
            raise IngestError(f"{writer.path}: the store gave {builder.n_docs} passages to index, it holds {n}")
        info = builder.save(bm25_dir)
        for f in bm25_dir.iterdir():  # files of a single index from an earlier, unsharded attempt
            if f.is_file() and f.name != SHARDS_FILE:
                f.unlink()
        parts = sorted(parts_dir.glob("part-*.npz"))
        (staging / "docmeta").mkdir(exist_ok=True)
        _write_npy_parts(staging / "docmeta" / "source_ids.npy", parts, "source_ids", np.int16, n)
        _write_npy_parts(staging / "docmeta" / "category_ids.npy", parts, "category_ids", np.int32, n)
        write_json(staging / "docmeta" / "names.json", {"sources": list(sources), "categories": list(categories)})
        shutil.rmtree(parts_dir, ignore_errors=True)
        del builder
        release_memory()
        prog["bm25"] = info
        write_json(prog_path, prog)
    info = prog["bm25"]

    done = int(prog["tantivy_rows"])
    if done < n:
        if done == 0:
            shutil.rmtree(staging / "tantivy", ignore_errors=True)
        else:
            echo(f"[kb] tantivy: resuming after {done:,} committed passages")
        every = max(1000, -(-n // 8))
        tv = TantivyBuilder(staging / "tantivy", heap_bytes=plan["tantivy_heap"], threads=plan["tantivy_threads"],
                            reuse=done > 0)
        bar = _tqdm(progress, total=n, initial=done, unit=" passages", desc="index tantivy")
        for rows in writer.iter_rows(batch=plan["batch"], after=done):
            for rowid, _doc_id, source, title, content, category, _ds, _prov in rows:
                tv.add(rowid - 1, indexed_text(title, content), source, category)
                if rowid % every == 0 and rowid < n:
                    tv.writer.commit()
                    prog["tantivy_rows"] = rowid
                    write_json(prog_path, prog)
                    echo(f"[kb] tantivy: passages 1-{rowid:,} committed (RSS {process_rss_bytes() >> 20} MB)")
                    kill_point("tantivy", rowid // every)
            bar.update(len(rows))
        bar.close()
        tv.close()
        del tv
        release_memory()
        prog["tantivy_rows"] = n
        write_json(prog_path, prog)
    prog_path.unlink()
    from kb_service.parallel_build import peak_rss_own_bytes

    peak = peak_rss_own_bytes() >> 20
    workers_peak = info.get("workers_peak_mb")
    echo(f"[kb] indexes written ({info['vocab']} terms, {info['postings']} postings in {info['shards']} bm25 shards; "
         f"peak RSS of this process {peak} MB"
         + (f", of each bm25 worker {', '.join(map(str, workers_peak))} MB" if workers_peak else "")
         + (f", budget {memory_budget_mb} MB)" if memory_budget_mb else ")"))
    shards = {"shard_docs": shard_docs or DEFAULT_SHARD_DOCS, "shards": info["shards"]}
    if memory_budget_mb is not None:
        shards["memory_budget_mb"] = memory_budget_mb
    if workers_peak:
        shards["workers"] = len(workers_peak)
        shards["peak_rss_mb"] = {"main": peak, "workers": workers_peak}
    return {"vocabulary": info["vocab"], "postings": info["postings"], "bm25_shards": shards}


def _build_parallel(writer, staging: Path, n: int, builder, units: list[list[int]], plan: dict,
                    shard_docs: int, context: dict, progress: bool, echo) -> dict:
    """`_build_indexes_sharded`'s two passes in `plan["workers"]` worker processes at once: the
    tantivy pass (one task, queued first) and the units' raw bm25 shards; then the units' filter
    ids renumbered as one corpus (`assemble_docmeta`), the adoption of the raw shards
    (committed) and `save` weighing them in the workers; returns once every task is done."""
    from kb_service.parallel_build import PARTS_DIR, WorkerPool, assemble_docmeta, tantivy_rows_done
    from kb_service.shards import SHARDS_FILE, kill_point

    bm25_dir, parts_dir = staging / "bm25", staging / PARTS_DIR
    if builder.committed_shards == 0:
        if builder.fresh:
            shutil.rmtree(parts_dir, ignore_errors=True)
            shutil.rmtree(bm25_dir, ignore_errors=True)
        builder.commit_start()  # so that a rerun keeps the units' commits under the same work dir
    tantivy_todo = tantivy_rows_done(staging) < n
    n_workers = max(1, min(plan["workers"], len(units) + tantivy_todo))
    bar = _tqdm(progress, total=n, unit=" passages", desc=f"index bm25s ({n_workers} workers)")
    seen = 0

    def on_message(msg: tuple) -> None:
        nonlocal seen
        if msg[0] == "echo":
            echo(msg[1])
        elif msg[0] == "rows":
            bar.update(msg[1])
        elif msg[0] == "shard":
            _kind, unit, spec = msg
            echo(f"[kb] bm25 unit {unit} {spec['dir']}: passages {spec['offset'] + 1:,}-"
                 f"{spec['offset'] + spec['num_docs']:,} committed ({spec['postings']:,} postings, "
                 f"{spec['vocab']:,} terms; worker RSS {spec['rss'] >> 20} MB)")
            seen += 1
            kill_point("bm25-shard", seen - 1)
        elif msg[0] == "tantivy":
            _kind, rows, every, rss = msg
            echo(f"[kb] tantivy: passages 1-{rows:,} committed (worker RSS {rss >> 20} MB)")
            kill_point("tantivy", rows // every)

    echo(f"[kb] bm25: {len(units)} unit(s) of passages" + (" and the tantivy pass" if tantivy_todo else "")
         + f" on {n_workers} worker process(es)")
    pool = WorkerPool(n_workers, plan["worker_share"], INDEX_HEADROOM_BYTES, MIN_WORKING_BYTES, on_message)
    try:
        if tantivy_todo:  # first: the longest task, alongside the units on the other workers
            pool.submit("tantivy", ("tantivy",), (str(writer.path), str(staging), n, plan["batch"],
                                                  TANTIVY_MIN_HEAP_PER_THREAD))
        if builder.committed_shards == 0:
            done: dict[int, list[dict]] = {}
            tasks = [("unit", u, (str(writer.path), str(staging), u, a, b, shard_docs, context, plan["batch"]))
                     for u, (a, b) in enumerate(units)]
            for key, result in pool.run([(kind, ("unit", u), args) for kind, u, args in tasks]):
                done[key[1]] = result["shards"]
            bar.close()
            shards = [s for u in range(len(units)) for s in done[u]]
            parts = [parts_dir / f"unit-{u:05d}" / f"part-{i:05d}.npz" for u in range(len(units))
                     for i in range(len(done[u]))]
            (staging / "docmeta").mkdir(exist_ok=True)
            assemble_docmeta(parts, staging / "docmeta", n)
            builder.adopt(shards)
            echo(f"[kb] bm25: {len(shards)} raw shards of {len(units)} unit(s) committed")
        else:
            bar.close()
            echo(f"[kb] bm25: resuming the weighting of {builder.committed_shards} adopted shard(s)")
        info = builder.save(bm25_dir, pool=pool)
        if tantivy_todo:
            for _key, result in pool.results([("tantivy",)]):
                echo(f"[kb] tantivy: all {result['rows']:,} passages committed (heap {result['heap'] >> 20} MB)")
    except BaseException:
        bar.close()
        pool.close(wait=False)  # a worker may be in the middle of a unit: stop it, its commits stay
        raise
    pool.close()
    for f in bm25_dir.iterdir():  # files of a single index from an earlier, unsharded attempt
        if f.is_file() and f.name != SHARDS_FILE:
            f.unlink()
    shutil.rmtree(parts_dir, ignore_errors=True)
    info["workers_peak_mb"] = sorted((v >> 20 for v in pool.peaks.values()), reverse=True)
    return info


def _provenance_by_source(writer) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    rows = writer.conn.execute(
        "SELECT p.source, v.json FROM (SELECT DISTINCT source, prov_id FROM passages) p "
        "JOIN provenance v ON v.id = p.prov_id ORDER BY p.source"
    )
    for source, js in rows:
        prov = json.loads(js)
        packages = [p.strip() for p in prov.get("package", "").split(",")]
        versions = [v.strip() for v in prov.get("version", "").split(",")]
        licenses = [x.strip() for x in prov.get("license", "").split(" | ")]
        if not prov.get("package") or not (len(packages) == len(versions) == len(licenses)):
            entries = [prov]  # free-form provenance of user data: keep as given
        else:
            entries = [{"package": p, "version": v, "license": x} for p, v, x in zip(packages, versions, licenses)]
        for entry in entries:
            if entry not in out.setdefault(source, []):
                out[source].append(entry)
    return out


def _publish(staging: Path, out: Path) -> None:
    old = None
    if out.exists():
        old = out.parent / f"{out.name}.old-{os.getpid()}-{int(time.time())}"
        os.replace(out, old)
    os.replace(staging, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _print_summary(report: BuildReport, echo) -> None:
    echo(f"[kb] built {report.out}: {report.n_passages} passages"
         + (f", {report.articles} articles" if report.articles else "") + f" in {report.seconds.get('total')}s")
    width = max((len(s) for s in report.sources), default=6)
    for source, count in sorted(report.sources.items(), key=lambda kv: -kv[1]):
        echo(f"[kb]   {source:<{width}}  {count:>9,}")
    for inp in report.inputs:
        extra = f", {inp['rejected']} rejected {inp.get('problems', '')}" if inp["rejected"] else ""
        echo(f"[kb]   input {Path(inp['input']).name}: {inp['inserted']} new, {inp['duplicates']} duplicate doc_ids{extra}")
