"""The passage store keeps long content zlib-compressed and short content as TEXT; every reader
(search, get, the single-process, bounded and parallel builds, resharding) sees the text as
ingested, and a store written before compression (all TEXT) reads the same."""

from __future__ import annotations

import json
import random
import sqlite3
from pathlib import Path

import pytest

from kb_service.ingest import build_kb, file_input
from kb_service.kb import KnowledgeBase
from kb_service.store import COMPRESS_MIN_BYTES, decode_content, encode_content, indexed_text

WORDS = ("myocardial infarction troponin aspirin heparin anticoagulation sepsis lactate bundle "
         "β-blocker µg/kg/min creatinine clearance eGFR naïve café").split()


def _passages(n: int = 240, seed: int = 5) -> list[dict]:
    rng = random.Random(seed)
    rows = []
    for i in range(n):
        # Two in three abstract-length (compressed), one in three a short line (kept as TEXT).
        size = rng.randint(60, 140) if i % 3 else rng.randint(3, 8)
        content = " ".join(rng.choice(WORDS) for _ in range(size)) + f" uniq{i}tok"
        rows.append({"doc_id": f"d{i}", "source": ("pubmed", "icd10")[i % 2], "title": f"Title {i}",
                     "content": content, "category": "c", "dataset_name": "fixture"})
    return rows


def _corpus(tmp_path: Path, rows: list[dict]) -> Path:
    path = tmp_path / "corpus.jsonl"
    path.write_text("".join(json.dumps(r, ensure_ascii=False) + "\n" for r in rows), encoding="utf-8")
    return path


def test_encode_keeps_short_text_and_round_trips_long_text():
    short = "I10 Essential (primary) hypertension"
    assert encode_content(short) is short
    long = "Heparin 80 units/kg IV bolus, then 18 units/kg/h; β-blocker within 24 h (naïve). " * 8
    packed = encode_content(long)
    assert isinstance(packed, bytes) and len(packed) < len(long.encode("utf-8")) / 2
    assert decode_content(packed) == long and decode_content(short) == short
    assert indexed_text("T", packed) == f"T\n{long}" and indexed_text("", packed) == long

def test_text_zlib_does_not_shrink_stays_text(monkeypatch):
    import kb_service.store as store

    long = "sepsis lactate " * 40
    monkeypatch.setattr(store.zlib, "compress", lambda raw, level: raw + b"\0")
    assert encode_content(long) is long


@pytest.mark.parametrize("how", ["in-memory", "parallel"])
def test_built_kb_stores_long_content_compressed_and_returns_it_as_ingested(tmp_path, how):
    rows = _passages()
    kwargs = {}
    if how == "parallel":
        from kb_service.shards import process_rss_bytes

        # The plan gives each worker a share of the budget less what this process holds, and wants
        # that share above this process's size (the workers are interpreters like it): in the full
        # suite pytest holds ~2 GB. Nothing of the budget is allocated.
        kwargs = {"memory_budget_mb": 3 * (process_rss_bytes() >> 20) + 2048, "workers": 2, "shard_docs": 100}
    build_kb([file_input(_corpus(tmp_path, rows))], tmp_path / "kb", progress=False, echo=lambda s: None, **kwargs)
    with sqlite3.connect(f"file:{tmp_path / 'kb' / 'passages.sqlite'}?mode=ro", uri=True) as db:
        kinds = dict(db.execute("SELECT doc_id, typeof(content) FROM passages"))
        stored = db.execute("SELECT sum(length(content)) FROM passages").fetchone()[0]
    for r in rows:
        long = len(r["content"].encode("utf-8")) >= COMPRESS_MIN_BYTES
        assert kinds[r["doc_id"]] == ("blob" if long else "text"), r["doc_id"]
    assert stored < 0.6 * sum(len(r["content"].encode("utf-8")) for r in rows)

    kb = KnowledgeBase.open(tmp_path / "kb")
    try:
        for r in rows[::7]:
            assert kb.get(r["doc_id"]).content == r["content"]
            # The indexes analysed the decoded text: a passage's own token finds it, in the bm25
            # ranking and in tantivy's query syntax alike.
            for query in (f"uniq{r['doc_id'][1:]}tok", f'"uniq{r["doc_id"][1:]}tok"'):
                hits = kb.search(query, k=1)
                assert [h.doc_id for h in hits] == [r["doc_id"]], query
                assert f"uniq{r['doc_id'][1:]}tok" in hits[0].snippet.replace("**", ""), hits[0].snippet
    finally:
        kb.close()


def test_store_written_before_compression_reads_the_same(tmp_path):
    rows = _passages(90)
    build_kb([file_input(_corpus(tmp_path, rows))], tmp_path / "kb", progress=False, echo=lambda s: None)
    kb = KnowledgeBase.open(tmp_path / "kb")
    before = [(h.doc_id, h.score, h.snippet) for h in kb.search("troponin heparin sepsis", k=20)]
    kb.close()
    # Rewrite every row as TEXT, as a store written before compression holds it.
    db = sqlite3.connect(tmp_path / "kb" / "passages.sqlite")
    db.create_function("decode_content", 1, decode_content)
    db.execute("UPDATE passages SET content = decode_content(content)")
    db.commit()
    assert db.execute("SELECT count(*) FROM passages WHERE typeof(content) != 'text'").fetchone()[0] == 0
    db.close()
    kb = KnowledgeBase.open(tmp_path / "kb")
    try:
        assert [(h.doc_id, h.score, h.snippet) for h in kb.search("troponin heparin sepsis", k=20)] == before
        assert all(kb.get(r["doc_id"]).content == r["content"] for r in rows)
    finally:
        kb.close()
