"""A missing, empty or corrupt KB fails at start-up with the path and the build command."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from kb_service.kb import KBCorruptError, KBNotBuiltError, KnowledgeBase
from kb_service.tools import KnowledgeTools


@pytest.fixture()
def broken(tmp_path, kb_dir):
    dst = tmp_path / "kb"
    shutil.copytree(kb_dir, dst)
    return dst


def test_missing_directory_names_path_and_command(tmp_path):
    path = tmp_path / "nope"
    with pytest.raises(KBNotBuiltError) as err:
        KnowledgeBase.open(path)
    msg = str(err.value)
    assert str(path) in msg and "hcgym kb build" in msg and "does not exist" in msg


def test_default_path_points_to_data_build(tmp_path, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path))
    with pytest.raises(KBNotBuiltError, match=r"hcgym data build") as err:
        KnowledgeBase.open()
    assert str(tmp_path / "kb") in str(err.value)


def test_empty_directory(tmp_path):
    (tmp_path / "kb").mkdir()
    with pytest.raises(KBNotBuiltError, match="no manifest.json"):
        KnowledgeBase.open(tmp_path / "kb")


def test_interrupted_build_is_reported(tmp_path):
    (tmp_path / "kb").mkdir()
    (tmp_path / "kb.building").mkdir()
    with pytest.raises(KBNotBuiltError, match="interrupted"):
        KnowledgeBase.open(tmp_path / "kb")


def test_zero_passages_manifest(broken):
    m = json.loads((broken / "manifest.json").read_text())
    m["n_passages"] = 0
    (broken / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(KBNotBuiltError, match="empty"):
        KnowledgeBase.open(broken)


def test_garbage_manifest(broken):
    (broken / "manifest.json").write_text("{not json")
    with pytest.raises(KBCorruptError, match="manifest.json"):
        KnowledgeBase.open(broken)


def test_corrupt_sqlite(broken):
    (broken / "passages.sqlite").write_bytes(b"this is not a database" * 100)
    with pytest.raises(KBCorruptError, match="passages.sqlite") as err:
        KnowledgeBase.open(broken)
    assert str(broken) in str(err.value) and "hcgym kb build" in str(err.value)


def test_truncated_bm25_matrix(broken):
    data = np.load(broken / "bm25" / "data.csc.index.npy")
    np.save(broken / "bm25" / "data.csc.index.npy", data[: len(data) // 2])
    with pytest.raises(KBCorruptError, match="bm25"):
        KnowledgeBase.open(broken)


def test_missing_index_file(broken):
    (broken / "bm25" / "indptr.csc.index.npy").unlink()
    with pytest.raises(KBCorruptError, match="indptr"):
        KnowledgeBase.open(broken)


def test_missing_tantivy(broken):
    shutil.rmtree(broken / "tantivy")
    with pytest.raises(KBCorruptError, match="tantivy"):
        KnowledgeBase.open(broken)


def test_count_mismatch(broken):
    m = json.loads((broken / "manifest.json").read_text())
    m["n_passages"] += 1
    (broken / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(KBCorruptError, match="manifest says"):
        KnowledgeBase.open(broken)


def test_tools_without_kb_report_build_command(tmp_path, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("HCGYM_KB_SERVICE", raising=False)
    tools = KnowledgeTools()
    for name, args in [("search", {"query": "asthma"}), ("search_pubmed", {"query": "asthma"}),
                       ("retrieve_evidence", {"query": "asthma"}), ("search_guidelines", {"query": "x"}),
                       ("search_medical_wiki", {"query": "x"}), ("browse_article", {"title": "Asthma"}),
                       ("get_passage", {"doc_id": "k:1"})]:
        out = tools.call(name, args)
        assert out.result is None, name
        assert "hcgym data build" in out.error and str(tmp_path / "kb") in out.error, out.error
