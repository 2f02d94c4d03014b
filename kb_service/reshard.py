"""`shard_kb`: a built knowledge base's single BM25 index turned into shards in place (`hcgym kb shard`,
`hcgym kb build --shard-docs`). Apart from `kb_service.shards` because it opens the KB to validate it,
and the KB opens shards."""

from __future__ import annotations

import json
from pathlib import Path

from kb_service.engines import write_json
from kb_service.shards import DEFAULT_SHARD_DOCS, SHARDS_FILE, ShardedBM25Builder, is_sharded
from kb_service.store import indexed_text


def shard_kb(path: Path, shard_docs: int = DEFAULT_SHARD_DOCS, progress: bool = False,
             echo=print, memory_budget_mb: int | None = None) -> dict:
    """Rewrite the bm25 index of the built KB at `path` as shards of `shard_docs` documents.

    The passages are read from the KB's store in row order and analysed exactly as the build
    does, so the sharded index ranks and scores as the single one did (tests/kb/test_shards.py).
    `shards.json` is written last; until then the KB keeps opening its single index, and the
    single index's files are removed only after it. The tantivy index (query syntax) is unchanged.

    `memory_budget_mb`: keep this process's peak RSS under it, as `build_kb`'s budget does: shards
    are also cut where their working set would pass what the budget leaves above what the process
    holds, and the passages are read in small batches.

    Raises:
        KBNotBuiltError / KBCorruptError: no valid KB at `path`.
        ValueError: `shard_docs` or `memory_budget_mb` is not a positive integer, the budget is below
            what the process holds plus a minimal working set (naming `memory_budget_mb`), or the
            KB is already sharded.
    """
    import sqlite3
    import time

    from kb_service.analysis import analyze
    from kb_service.kb import KnowledgeBase

    from kb_service.ingest import _memory_plan

    if memory_budget_mb is not None and (isinstance(memory_budget_mb, bool) or not isinstance(memory_budget_mb, int)
                                         or memory_budget_mb < 1):
        raise ValueError(f"memory_budget_mb must be a positive integer or None, got {memory_budget_mb!r}")
    plan = _memory_plan(memory_budget_mb, lambda _s: None, workers=1)  # refuses a budget too small to work in
    path = Path(path)
    kb = KnowledgeBase.open(path, warmup=False)  # validates the KB (and names the build command)
    n = kb.n_passages
    kb.close()
    bm25_dir = path / "bm25"
    if is_sharded(bm25_dir):
        have = json.loads((bm25_dir / SHARDS_FILE).read_text(encoding="utf-8"))
        raise ValueError(f"the knowledge base at {path} is already sharded ({len(have['shards'])} shards of "
                         f"{have.get('shard_docs')} documents); rebuild it (hcgym kb build --force ...) to reshard")
    t0 = time.perf_counter()
    builder = ShardedBM25Builder(path / "bm25.raw", shard_docs=shard_docs, memory_bytes=plan["bm25_bytes"])
    conn = sqlite3.connect(f"file:{path / 'passages.sqlite'}?mode=ro", uri=True)
    try:
        from tqdm import tqdm

        bar = tqdm(total=n, unit=" passages", desc="shard bm25", disable=not progress, mininterval=1.0)
        last = 0
        while True:
            rows = conn.execute("SELECT rowid, title, content FROM passages WHERE rowid > ? ORDER BY rowid LIMIT ?",
                                (last, 20000 if memory_budget_mb is None else plan["batch"])).fetchall()
            if not rows:
                break
            for rowid, title, content in rows:
                builder.add(analyze(indexed_text(title, content)))
            last = rows[-1][0]
            bar.update(len(rows))
        bar.close()
    finally:
        conn.close()
    if builder.n_docs != n:
        raise ValueError(f"{path / 'passages.sqlite'} gave {builder.n_docs} passages, the manifest says {n}")
    info = builder.save(bm25_dir)
    for f in bm25_dir.iterdir():  # the single index, now superseded by shards.json
        if f.is_file() and f.name != SHARDS_FILE:
            f.unlink()
    manifest_path = path / "manifest.json"
    manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    manifest.setdefault("engine", {})["bm25_shards"] = {"shard_docs": shard_docs, "shards": info["shards"],
                                                        **({"memory_budget_mb": memory_budget_mb}
                                                           if memory_budget_mb is not None else {})}
    write_json(manifest_path, manifest)
    info["seconds"] = round(time.perf_counter() - t0, 1)
    echo(f"[kb] {path}: bm25 index rewritten as {info['shards']} shards of up to {shard_docs} passages "
         f"({info['postings']} postings, {info['seconds']}s)")
    return info
