"""Article store, and the agent knowledge tools over the fixture KB."""

from __future__ import annotations

import pytest

from kb_service.pages import PageStore, PageStoreWriter, article_passages, build_page_store, title_key
from kb_service.tools import KnowledgeTools

from conftest import ARTICLES


def test_page_store_roundtrip_many_blocks(tmp_path):
    arts = [{"title": f"Article {i}", "url": f"https://w/{i}", "text": f"body {i} " + "x" * (i * 997 % 50_000)}
            for i in range(300)]
    info = build_page_store(arts + [{"title": "article 5", "url": "dup", "text": "dup"}], tmp_path / "s")
    assert info == {"articles": 300, "duplicates": 1}
    store = PageStore(tmp_path / "s")
    assert len(store) == 300
    raw = (tmp_path / "s" / "pages.zlib").stat().st_size
    assert raw < sum(len(a["text"]) for a in arts) / 5  # compressed
    for i in (0, 1, 150, 299):
        art = store.get(f"Article {i}")
        assert art.text == arts[i]["text"] and art.url == f"https://w/{i}"
    assert store.get("https://w/42").title == "Article 42"
    assert store.get("ARTICLE_7").title == "Article 7"  # case, underscores
    assert store.get("Article 300") is None and store.get("") is None
    assert store.suggest("article 2") == ["Article 2", "Article 20", "Article 200", "Article 201", "Article 202"]


def test_title_key():
    assert title_key("Café_au  Lait") == title_key("cafe au lait")


def test_article_passages_split_and_titles():
    text = "\n".join(f"Paragraph {i} " + "word " * 90 for i in range(7))
    parts = list(article_passages({"title": "Big", "url": "u", "text": text}, source="wikipedia"))
    assert len(parts) >= 3 and parts[0]["title"] == "Big" and parts[1]["title"] == "Big § 2"
    assert all(p["doc_id"].startswith("wikipedia:u#") for p in parts)
    assert " ".join(p["content"] for p in parts).split() == text.split()


def test_kb_article_lookup(kb):
    assert kb.article("heart failure").url == ARTICLES[0]["url"]
    assert kb.article("Kawasaki disease § 2").title == "Kawasaki disease"
    with pytest.raises(KeyError, match="Kawasaki"):
        kb.article("Kawasaki")
    hits = kb.search("kawasaki immunoglobulin", k=3, source="wikipedia")
    assert hits[0].doc_id == "wikipedia:https://en.wikipedia.org/wiki/Kawasaki_disease#1"


@pytest.fixture()
def tools(kb):
    return KnowledgeTools(kb)


def test_tool_schemas(tools):
    names = set(tools.tool_names)
    assert names == {"search", "search_pubmed", "retrieve_evidence", "search_medical_wiki", "browse_article",
                     "search_guidelines", "get_passage"}
    schema = {s["function"]["name"]: s["function"] for s in tools.schemas()}
    assert schema["search"]["parameters"]["required"] == ["query"]
    assert "BM25" in schema["search"]["description"]
    assert schema["browse_article"]["parameters"]["properties"]["title"]["description"]


def test_search_tool_returns_doc_ids(tools, kb):
    out = tools.call("search", {"query": "pheochromocytoma", "k": 2})
    assert out.error is None
    res = out.result["results"]
    assert [r["doc_id"] for r in res] == ["k:pheo3", "k:pheo1"]
    assert out.result["sources_searched"] == "all"
    for r in res:
        assert kb.get(r["doc_id"]).doc_id == r["doc_id"]
    empty = tools.call("search", {"query": "zzzqqq"}).result
    assert empty["results"] == [] and "No passage matched" in empty["note"]
    bad = tools.call("search", {"query": "x", "source": "pubmed"})
    assert bad.result is None and "available" in bad.error


def test_search_pubmed_says_what_it_searched(tools):
    out = tools.call("search_pubmed", {"query": "pheochromocytoma"}).result
    assert out["sources_searched"] == ["guidelines"]
    assert "No PubMed" in out["note"]
    assert all(r["source"] == "guidelines" for r in out["results"])
    assert not any("pmid" in str(k).lower() for r in out["results"] for k in r)


def test_wiki_guidelines_evidence_browse(tools):
    wiki = tools.call("search_medical_wiki", {"query": "kawasaki"}).result
    assert wiki["sources_searched"] == ["wiki", "wikipedia"]
    assert wiki["results"][0]["title"] == "Kawasaki disease"
    page = tools.call("browse_article", {"title": wiki["results"][0]["title"], "max_chars": 500}).result
    assert page["url"].endswith("Kawasaki_disease") and "immunoglobulin" in page["text"]
    long = tools.call("browse_article", {"title": "Pneumonie", "max_chars": 500}).result
    assert long["next_offset"] == 500 and len(long["text"]) == 500
    nxt = tools.call("browse_article", {"title": "Pneumonie", "offset": 500, "max_chars": 500}).result
    assert nxt["offset"] == 500
    missing = tools.call("browse_article", {"title": "No such page"})
    assert missing.result is None and "no article titled" in missing.error
    guide = tools.call("search_guidelines", {"query": "heart failure"}).result
    assert guide["sources_searched"] == ["guidelines"] and guide["results"][0]["doc_id"] == "k:hf"
    ev = tools.call("retrieve_evidence", {"query": "warfarin INR", "k": 1}).result
    assert ev["results"][0]["doc_id"] == "k:warfarin" and "vitamin K antagonist" in ev["results"][0]["text"]


def test_get_passage_unknown_id_is_tool_error(tools):
    ok = tools.call("get_passage", {"doc_id": "k:cough"})
    assert ok.result["content"].startswith("Pertussis")
    bad = tools.call("get_passage", {"doc_id": "PMID:12345"})
    assert bad.result is None and "PMID:12345" in bad.error


def test_writer_rejects_nothing_silently(tmp_path):
    w = PageStoreWriter(tmp_path / "p")
    assert w.add("A", "text") and not w.add("a", "other") and not w.add("  ", "x")
    assert w.close() == {"articles": 1, "duplicates": 2}
