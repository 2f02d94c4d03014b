"""MedRAG corpora imported as distributed (corpus/<name>/chunk/*.jsonl), and a sharded KB that
ranks and scores exactly as the single-index KB over the same passages."""

from __future__ import annotations

import json
import random
import shutil
from pathlib import Path

import pytest

from kb_service.sources.medrag import BadRow, MedRAGFormatError, MedRAGPassage, find_corpora, read_corpus

FIXTURES = Path(__file__).parent / "fixtures" / "medrag"
COUNTS = {"pubmed": 5, "statpearls": 4, "textbooks": 4, "wikipedia": 4}


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").split("\n") if line.strip()]


def test_fixtures_are_in_medrag_layout():
    # As MedRAG's src/data/*.py write them: "\n".join(json.dumps(...)), no newline after the last
    # line, ASCII escapes, every line with id, title, content and contents = title + ". " + content.
    for corpus, files in find_corpora(FIXTURES).items():
        for f in files:
            raw = f.read_bytes()
            assert not raw.endswith(b"\n") and raw.isascii(), f
            for rec in _lines(f):
                assert set(rec) == {"id", "title", "content", "contents"}
                assert rec["contents"] in (f"{rec['title']}. {rec['content']}", f"{rec['title']} {rec['content']}")


def test_find_corpora_accepts_the_three_roots():
    found = find_corpora(FIXTURES)
    assert list(found) == ["pubmed", "statpearls", "textbooks", "wikipedia"]
    assert [f.name for f in found["pubmed"]] == ["pubmed24n0001.jsonl", "pubmed24n0002.jsonl"]
    assert find_corpora(FIXTURES / "textbooks") == {"textbooks": found["textbooks"]}
    assert find_corpora(FIXTURES / "statpearls" / "chunk") == {"statpearls": found["statpearls"]}


def test_find_corpora_errors_name_the_path(tmp_path):
    with pytest.raises(MedRAGFormatError, match=f"{tmp_path / 'nope'} does not exist"):
        find_corpora(tmp_path / "nope")
    (tmp_path / "pubmed").mkdir()
    with pytest.raises(MedRAGFormatError, match="expected <corpus>/chunk/\\*.jsonl"):
        find_corpora(tmp_path)
    (tmp_path / "pubmed" / "chunk").mkdir()
    (tmp_path / "pubmed" / "chunk" / "notes.txt").write_text("x")
    with pytest.raises(MedRAGFormatError, match="holds no .jsonl chunk files"):
        find_corpora(tmp_path)


def test_every_line_becomes_a_passage_with_its_provenance():
    for corpus, files in find_corpora(FIXTURES).items():
        got = list(read_corpus(files, corpus))
        assert len(got) == COUNTS[corpus] and all(isinstance(p, MedRAGPassage) for p in got)
        expected = [(f, n, rec) for f in files for n, rec in enumerate(_lines(f), 1)]
        for p, (f, n, rec) in zip(got, expected):
            assert p.provenance == {"corpus": corpus, "file": f"{corpus}/chunk/{f.name}", "line": str(n),
                                    "id": rec["id"]}
            assert (p.id, p.title, p.content) == (rec["id"], rec["title"], rec["content"])
    sj = next(p for p in read_corpus(find_corpora(FIXTURES)["pubmed"], "pubmed") if p.id == "PMID:10000202")
    assert sj.title.startswith("Sjögren") and sj.line == 2  # \u00f6 escape decoded
    sp = next(read_corpus(find_corpora(FIXTURES)["statpearls"], "statpearls")).passage()
    assert sp["category"] == "Acute Pancreatitis" and sp["source"] == "statpearls"
    assert sp["dataset_name"] == "MedRAG/statpearls"
    assert sp["provenance"] == {"dataset": "MedRAG/statpearls", "corpus": "statpearls",
                                "file": "statpearls/chunk/article-17.jsonl"}


BAD_LINES = [
    '{"id": "PMID:9", "title": "Truncated", "content": "abc',  # invalid JSON
    '["PMID:8", "not an object"]',
    '{"title": "No id", "content": "text"}',
    '{"id": "PMID:7", "title": "Empty", "content": "  ", "contents": ""}',
    '{"id": "PMID:6", "title": "Only contents", "contents": "Only contents. Fallback text is indexed."}',
    '{"id": "PMID:5", "title": 3, "content": "x"}',
]


def _bad_copy(tmp_path: Path) -> Path:
    root = tmp_path / "corpus"
    shutil.copytree(FIXTURES, root)
    f = root / "pubmed" / "chunk" / "pubmed24n0002.jsonl"
    f.write_text(f.read_text() + "\n\n" + "\n".join(BAD_LINES))  # a blank line too, as a stray edit leaves
    return root


def test_bad_rows_are_skipped_and_reported_with_file_and_line(tmp_path):
    root = _bad_copy(tmp_path)
    got = list(read_corpus(find_corpora(root)["pubmed"], "pubmed"))
    bad = [str(b) for b in got if isinstance(b, BadRow)]
    assert bad == [
        "pubmed/chunk/pubmed24n0002.jsonl line 4: invalid JSON, column 51: Unterminated string starting at",
        "pubmed/chunk/pubmed24n0002.jsonl line 5: not a JSON object (list)",
        "pubmed/chunk/pubmed24n0002.jsonl line 6: missing or empty 'id'",
        "pubmed/chunk/pubmed24n0002.jsonl line 7: PMID:7: no text ('content' and 'contents' missing or empty)",
        "pubmed/chunk/pubmed24n0002.jsonl line 9: PMID:5: 'title' is int, not a string",
    ]
    fallback = next(p for p in got if isinstance(p, MedRAGPassage) and p.id == "PMID:6")
    assert fallback.content == "Fallback text is indexed." and fallback.line == 8
    with pytest.raises(MedRAGFormatError, match=r"MedRAG pubmed: pubmed/chunk/pubmed24n0002.jsonl line 4: invalid JSON"):
        list(read_corpus(find_corpora(root)["pubmed"], "pubmed", strict=True))


def _hcgym(*argv: str) -> int:
    from envs.cli import main

    return main(list(argv))


def test_cli_import_reports_bad_rows_and_strict_stops(tmp_path, capsys):
    root = _bad_copy(tmp_path)
    out = tmp_path / "kb"
    assert _hcgym("kb", "build", "--medrag", str(root), "--medrag-corpus", "pubmed", "--out", str(out),
                  "--quiet", "--json") == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sources"] == {"pubmed": 6}  # 5 + the contents-only line
    (inp,) = summary["inputs"]
    assert inp["rejected"] == 5 and len(inp["problems"]) == 5
    assert inp["problems"][1] == "pubmed/chunk/pubmed24n0002.jsonl line 5: not a JSON object (list)"
    rc = _hcgym("kb", "build", "--medrag", str(root), "--strict", "--out", str(tmp_path / "strict"), "--quiet",
                "--force")
    assert rc == 2
    assert "pubmed/chunk/pubmed24n0002.jsonl line 4: invalid JSON" in capsys.readouterr().err
    assert _hcgym("kb", "build", "--medrag", str(root), "--medrag-corpus", "cochrane", "--out",
                  str(tmp_path / "x"), "--quiet") == 2
    assert "no corpus cochrane (found: pubmed, statpearls, textbooks, wikipedia)" in capsys.readouterr().err


@pytest.fixture(scope="module")
def medrag_kbs(tmp_path_factory):
    """The four fixture corpora imported with the CLI, once as one index and once sharded."""
    tmp = tmp_path_factory.mktemp("medrag")
    single, sharded = tmp / "single", tmp / "sharded"
    assert _hcgym("kb", "build", "--medrag", str(FIXTURES), "--out", str(single), "--quiet") == 0
    assert _hcgym("kb", "build", "--medrag", str(FIXTURES), "--out", str(sharded), "--shard-docs", "4",
                  "--quiet") == 0
    from kb_service.kb import KnowledgeBase

    return KnowledgeBase.open(single), KnowledgeBase.open(sharded)


def test_medrag_kb_search_get_and_provenance(medrag_kbs):
    single, sharded = medrag_kbs
    from kb_service.shards import ShardedBM25Searcher

    assert isinstance(sharded.bm25, ShardedBM25Searcher) and len(sharded.bm25.shards) == 5  # 17 passages / 4
    assert sharded.stats()["engine"]["bm25_shards"] == {"shard_docs": 4, "shards": 5}
    for kb in medrag_kbs:
        assert kb.stats()["sources"] == COUNTS
        hits = kb.search("pheochromocytoma metanephrines", k=3)
        assert hits[0].doc_id == "InternalMed_Harrison_1" and hits[0].source == "textbooks"
        assert kb.search("warfarin INR", k=1, source="pubmed")[0].doc_id == "PMID:10000201"
        p = kb.get("article-2034_1")
        assert p.category == "Hyperkalemia" and p.dataset_name == "MedRAG/statpearls"
        assert p.provenance == {"dataset": "MedRAG/statpearls", "corpus": "statpearls",
                                "file": "statpearls/chunk/article-2034.jsonl"}
        assert kb.search('"brachial plexus"', k=1)[0].doc_id == "Anatomy_Gray_0"  # tantivy path unchanged


def _words(kb) -> list[str]:
    words = set()
    for rows in [kb.store.rows_by_index(range(kb.n_passages))]:
        for row in rows.values():
            words.update(w.strip(".,;:()?").lower() for w in (row[3] + " " + row[4]).split())
    return sorted(w for w in words if w)


def _assert_same_rankings(single, sharded, seed: int, trials: int, filters: list) -> int:
    rng = random.Random(seed)
    words = _words(single)
    matched = 0
    for trial in range(trials):
        query = " ".join(rng.choice(words) for _ in range(rng.choice([1, 2, 3, 6, 40])))
        k = rng.choice([1, 3, 10, 1000])
        flt = filters[trial % len(filters)]
        a = single.rank(query, k=k, **flt)
        b = sharded.rank(query, k=k, **flt)
        assert [d for d, _ in a] == [d for d, _ in b], (query, k, flt)
        assert all(abs(x - y) <= 1e-6 for (_, x), (_, y) in zip(a, b)), (query, k, flt)
        matched += bool(a)
    return matched


def test_sharded_kb_ranks_exactly_as_single_on_medrag_fixtures(medrag_kbs):
    single, sharded = medrag_kbs
    filters = [{}, {"source": "pubmed"}, {"source": ["textbooks", "wikipedia"]}, {"category": "Autism"}]
    assert _assert_same_rankings(single, sharded, seed=2, trials=300, filters=filters) > 120


def test_shard_command_on_a_built_kb_ranks_exactly_as_before(kb_dir, kb, tmp_path):
    """The tests' session KB (hand-made passages + 400 seeded filler, articles) resharded in place
    with `hcgym kb shard` ranks every query exactly as the original."""
    from kb_service.kb import KnowledgeBase

    copy = tmp_path / "kb"
    shutil.copytree(kb_dir, copy)
    # Under a budget that these 97-passage shards fit: the shards are those of --shard-docs alone.
    assert _hcgym("kb", "shard", "--path", str(copy), "--shard-docs", "97", "--memory-budget-mb", "4096",
                  "--quiet") == 0
    sharded = KnowledgeBase.open(copy)
    assert len(sharded.bm25.shards) == -(-kb.n_passages // 97)
    assert sharded.manifest["engine"]["bm25_shards"]["memory_budget_mb"] == 4096
    assert not (copy / "bm25" / "data.csc.index.npy").exists()  # the single index is gone
    filters = [{}, {"source": "guidelines"}, {"category": "cardiology"}, {"source": ["wiki", "drugs"]}]
    assert _assert_same_rankings(kb, sharded, seed=9, trials=300, filters=filters) > 250
    from kb_service.kb import KBCorruptError
    from kb_service.reshard import shard_kb

    with pytest.raises(ValueError, match="already sharded"):
        shard_kb(copy, 50)
    shutil.rmtree(copy / "bm25" / "shard-00002")
    with pytest.raises(KBCorruptError, match="unreadable bm25 index"):
        KnowledgeBase.open(copy)


def test_resume_skips_exactly_the_lines_already_ingested(tmp_path):
    """A build resumes a corpus after the lines it committed (bad rows and blank lines included in
    the count the way the build counts them): skipping n gives the tail of the full read."""
    root = _bad_copy(tmp_path)
    files = find_corpora(root)["pubmed"]
    full = list(read_corpus(files, "pubmed"))
    for n in (0, 1, 3, 4, 7, len(full)):
        assert list(read_corpus(files, "pubmed", skip=n)) == full[n:]
