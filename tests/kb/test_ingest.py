"""Ingestion: JSONL/Parquet/FTS5 reference import, dedup, rejects, resume, CLI."""

from __future__ import annotations

import gzip
import json
import sqlite3

import pytest

from kb_service.ingest import IngestError, Input, build_kb, file_input, iterable_input
from kb_service.kb import KnowledgeBase

from conftest import write_jsonl

DOCS = [
    {"doc_id": f"d{i}", "source": "s1" if i % 2 else "s2", "title": f"Title {i}",
     "content": f"passage number {i} about {'sarcoidosis' if i == 7 else 'medicine'} and word{i}",
     "category": "c", "dataset_name": "ds"}
    for i in range(40)
]


def quiet(**kw):
    return dict(progress=False, echo=lambda s: None, **kw)


def test_jsonl_gz_dedup_and_rejects(tmp_path):
    lines = [json.dumps(d) for d in DOCS]
    lines += [json.dumps({**DOCS[3], "content": "a later duplicate"}), "{broken json", json.dumps({"doc_id": "x"}),
              json.dumps({"doc_id": "y", "source": "s1", "content": "   "}), "[1, 2]", ""]
    path = tmp_path / "p.jsonl.gz"
    with gzip.open(path, "wt", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    summary = build_kb([file_input(path)], tmp_path / "kb", **quiet())
    assert summary["n_passages"] == 40
    assert summary["sources"] == {"s1": 20, "s2": 20}
    inp = summary["inputs"][0]
    assert inp["duplicates"] == 1 and inp["rejected"] == 4
    assert any("invalid JSON" in p for p in inp["problems"]) and any("missing source" in p for p in inp["problems"])
    kb = KnowledgeBase.open(tmp_path / "kb")
    assert kb.get("d3").content.startswith("passage number 3")  # first occurrence wins
    assert kb.search("sarcoidosis", k=3)[0].doc_id == "d7"


def test_parquet_input(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist(DOCS)
    pq.write_table(table, tmp_path / "p.parquet", row_group_size=7)
    summary = build_kb([file_input(tmp_path / "p.parquet")], tmp_path / "kb", **quiet())
    assert summary["n_passages"] == 40
    kb = KnowledgeBase.open(tmp_path / "kb")
    assert kb.search("word13", k=1)[0].doc_id == "d13"


def make_reference_fts5(path, docs):
    conn = sqlite3.connect(path)
    conn.execute("CREATE VIRTUAL TABLE passages_fts USING fts5(doc_id, source, title, content, category, "
                 "dataset_name, tokenize='porter unicode61')")
    conn.executemany("INSERT INTO passages_fts VALUES (?,?,?,?,?,?)",
                     [(d["doc_id"], d["source"], d["title"], d["content"], d["category"], d["dataset_name"])
                      for d in docs])
    conn.commit()
    conn.close()


def test_import_reference_fts5_database(tmp_path):
    ref = tmp_path / "medical_knowledge.db"
    make_reference_fts5(ref, DOCS)
    # the reference's own FTS5 query finds the same top passage as our KB
    conn = sqlite3.connect(ref)
    ref_top = conn.execute("SELECT doc_id FROM passages_fts WHERE passages_fts MATCH 'sarcoidosis' "
                           "ORDER BY bm25(passages_fts) LIMIT 1").fetchone()[0]
    conn.close()
    summary = build_kb([file_input(ref)], tmp_path / "kb", **quiet())
    assert summary["n_passages"] == 40 and summary["inputs"][0]["rows"] == 40
    kb = KnowledgeBase.open(tmp_path / "kb")
    assert kb.search("sarcoidosis", k=1)[0].doc_id == ref_top == "d7"
    p = kb.get("d8")
    assert (p.source, p.title, p.category, p.dataset_name) == ("s2", "Title 8", "c", "ds")


def test_reference_layout_errors(tmp_path):
    bad = tmp_path / "other.db"
    conn = sqlite3.connect(bad)
    conn.execute("CREATE TABLE something(x)")
    conn.commit()
    conn.close()
    with pytest.raises(IngestError, match="passages_fts"):
        file_input(bad)
    with pytest.raises(IngestError, match="unknown input format"):
        file_input(write_jsonl(tmp_path / "x.csv", DOCS))
    with pytest.raises(IngestError, match="does not exist"):
        file_input(tmp_path / "missing.jsonl")


def test_all_rejected_is_an_error(tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text('{"doc_id": "a"}\n')
    with pytest.raises(IngestError, match="0 valid records"):
        build_kb([file_input(path)], tmp_path / "kb", **quiet())
    assert not (tmp_path / "kb").exists()


class Boom(Exception):
    pass


def test_resume_after_interruption(tmp_path):
    out = tmp_path / "kb"
    first = iterable_input("docs", "v1", lambda: iter(DOCS[:10]))

    def failing():
        for i, d in enumerate(DOCS[10:]):
            if i == 17:
                raise Boom("killed")
            yield d

    with pytest.raises(Boom):
        build_kb([first, iterable_input("more", "v1", failing)], out, batch_size=5, **quiet())
    assert not out.exists() and (tmp_path / "kb.building").exists()
    with pytest.raises(Exception, match="interrupted"):
        KnowledgeBase.open(out)

    seen: list[int] = []

    def counting_open(skip: int):
        seen.append(skip)
        return iter(DOCS[10 + skip:])

    more = Input("more", "v1", counting_open)
    summary = build_kb([first, more], out, batch_size=5, **quiet())
    assert seen == [15]  # three batches of 5 were committed before the failure
    assert summary["n_passages"] == 40
    assert summary["inputs"][0].get("resumed") == "already complete"
    assert summary["inputs"][1]["resumed_from"] == 15 and summary["inputs"][1]["duplicates"] == 0
    kb = KnowledgeBase.open(out)
    assert {kb.get(f"d{i}").doc_id for i in range(40)} == {f"d{i}" for i in range(40)}


def test_changed_input_restarts(tmp_path):
    out = tmp_path / "kb"
    def failing():
        for i, d in enumerate(DOCS):
            if i == 30:
                raise Boom("killed")
            yield d

    with pytest.raises(Boom):
        build_kb([iterable_input("a", "v1", failing)], out, batch_size=5, **quiet())
    summary = build_kb([iterable_input("a", "v2", lambda: iter(DOCS[:12]))], out, **quiet())
    assert summary["n_passages"] == 12


def test_rebuild_replaces_published_kb(tmp_path):
    out = tmp_path / "kb"
    build_kb([iterable_input("a", "v1", lambda: iter(DOCS))], out, **quiet())
    kb_old = KnowledgeBase.open(out)
    build_kb([iterable_input("a", "v1", lambda: iter(DOCS[:5]))], out, resume=False, **quiet())
    assert KnowledgeBase.open(out).n_passages == 5
    assert kb_old.n_passages == 40


def test_cli_build_stats_search(tmp_path, capsys):
    from envs.cli import main

    src = write_jsonl(tmp_path / "p.jsonl", DOCS)
    out = tmp_path / "kb"
    assert main(["kb", "build", str(src), "--out", str(out), "--quiet", "--json"]) == 0
    built = json.loads(capsys.readouterr().out)
    assert built["n_passages"] == 40
    assert main(["kb", "stats", "--path", str(out), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["sources"] == {"s1": 20, "s2": 20} and stats["n_passages"] == 40
    assert main(["kb", "search", "sarcoidosis", "--path", str(out), "--json", "-k", "3"]) == 0
    hits = json.loads(capsys.readouterr().out)
    assert hits[0]["doc_id"] == "d7" and "**sarcoidosis**" in hits[0]["snippet"]
    assert main(["kb", "search", "x", "--path", str(tmp_path / "missing")]) == 2
    assert "hcgym kb build" in capsys.readouterr().err
