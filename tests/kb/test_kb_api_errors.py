"""The knowledge base's direct API (`KnowledgeBase.search / rank / get / article`, `StoreReader`)
refuses bad arguments with an error naming the argument, and the KB service's actors survive every
one of them."""

from __future__ import annotations

import numpy as np
import pytest

from kb_service.kb import MAX_K, UnknownDocError

BAD_K = [(float("inf"), TypeError, "k must be an integer"), (float("nan"), TypeError, "k must be an integer"),
         (2.0, TypeError, "got float 2.0"), (True, TypeError, "got bool True"), ("5", TypeError, "got str"),
         (None, TypeError, "got NoneType"), (-1, ValueError, "k must be between 0 and 1000, got -1"),
         (MAX_K + 1, ValueError, "got 1001"), (10**30, ValueError, "k must be between 0 and 1000")]

SURROGATES = ["\ud800", "heart \udfff failure", "k:warfarin\udc80"]


@pytest.mark.parametrize("k, error, message", BAD_K, ids=lambda v: repr(v)[:20])
def test_bad_k_is_refused_naming_k(kb, k, error, message):
    with pytest.raises(error, match=message):
        kb.search("heart failure", k=k)
    with pytest.raises(error, match=message):
        kb.rank("heart failure", k=k)


def test_good_k_values(kb):
    assert kb.search("heart", k=0) == []
    assert len(kb.search("heart", k=np.int64(2))) == 2  # numpy integers are integers
    assert len(kb.search("patient", k=MAX_K)) <= MAX_K


@pytest.mark.parametrize("source, message", [(123, "source must be a source name or a list of them, got int"),
                                             (b"wiki", "got bytes"), ({"wiki": 1}, "got dict"),
                                             (["wiki", 5], r"source\[1\] must be a source name \(str\), got int"),
                                             (("drugs", None), r"source\[1\] .* got NoneType")])
def test_bad_source_type_is_refused_naming_source(kb, source, message):
    with pytest.raises(TypeError, match=message):
        kb.search("warfarin", source=source)


def test_sources_by_name_still_work(kb):
    assert [p.doc_id for p in kb.search("warfarin", k=1, source="drugs")] == ["k:warfarin"]
    assert [p.doc_id for p in kb.search("warfarin", k=1, source=("drugs", "wiki"))] == ["k:warfarin"]
    with pytest.raises(ValueError, match="unknown source '\\\\ud800'"):
        kb.search("warfarin", source="\ud800")  # not a source; named, not a crash


def test_bad_category_type_is_refused(kb):
    with pytest.raises(TypeError, match="category must be a category name"):
        kb.search("heart", category=3)
    assert kb.search("heart", category="no such category") == []


@pytest.mark.parametrize("doc_id", SURROGATES, ids=["alone", "inside", "trailing"])
def test_lone_surrogates_in_get_name_doc_id(kb, doc_id):
    with pytest.raises(ValueError, match=r"doc_id holds a lone surrogate \(U\+D[89A-F][0-9A-F]{2}\) at position \d+"):
        kb.get(doc_id)


@pytest.mark.parametrize("title", SURROGATES, ids=["alone", "inside", "trailing"])
def test_lone_surrogates_in_article_name_the_title(kb, title):
    with pytest.raises(ValueError, match="title_or_url holds a lone surrogate"):
        kb.article(title)


def test_get_and_article_types(kb):
    with pytest.raises(TypeError, match="doc_id must be a str, got list"):
        kb.get(["k:warfarin"])
    with pytest.raises(UnknownDocError):
        kb.get(12345)  # an int is read as its digits: simply unknown here
    with pytest.raises(TypeError, match="title_or_url must be a str, got int"):
        kb.article(42)
    assert kb.article("Heart failure").title == "Heart failure"


def test_surrogates_in_queries_are_just_text(kb):
    # Queries are free text: a surrogate is a character that matches nothing, never an error.
    for query in ('"\ud800 heart"', "heart AND \ud800", "title:\udfff", '"heart \udc80failure"'):
        assert isinstance(kb.search(query, k=3), list)


def test_store_reader_names_its_arguments(kb):
    with pytest.raises(TypeError, match=r"doc_indices\[1\] must be an integer, got float"):
        kb.store.rows_by_index([0, float("inf")])
    with pytest.raises(ValueError, match=r"doc_indices\[0\] must be a document number >= 0, got -3"):
        kb.store.rows_by_index([-3])
    with pytest.raises(ValueError, match="doc_id holds a lone surrogate"):
        kb.store.row_by_doc_id("\ud800")
    assert set(kb.store.rows_by_index([np.int64(0), 1])) == {0, 1}
    assert kb.store.rows_by_index([10**12]) == {}  # past the last row: absent, as before


@pytest.mark.ray
def test_service_actor_survives_every_bad_argument(kb_dir):
    ray = pytest.importorskip("ray")
    from envs._runtime import init_ray
    from kb_service.service import start_kb_service

    started = not ray.is_initialized()
    if started:
        init_ray("local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    client = start_kb_service(replicas=1, path=kb_dir, name="kb-api-errors", num_cpus=0.25)
    try:
        before = client.search("asthma corticosteroid", k=3)
        for k, error, message in BAD_K:
            with pytest.raises(error, match=message):  # Ray re-raises the actor's error as its own class
                client.search("asthma", k=k)
        with pytest.raises(TypeError, match="source must be a source name"):
            client.search("asthma", source=123)
        for text in SURROGATES:
            with pytest.raises(ValueError, match="doc_id holds a lone surrogate"):
                client.get(text)
            with pytest.raises(ValueError, match="title_or_url holds a lone surrogate"):
                client.article(text)
        # The same replica answers, identically, after all of that.
        assert [p.doc_id for p in client.search("asthma corticosteroid", k=3)] == [p.doc_id for p in before]
        assert client.get("k:warfarin").content.startswith("Warfarin")
    finally:
        client.shutdown()
        if started:
            ray.shutdown()
