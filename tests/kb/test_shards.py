"""Sharded BM25 index: the same results and scores as one index over the same corpus."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest

from kb_service.analysis import MAX_QUERY_TERMS
from kb_service.engines import BM25Builder, BM25Searcher
from kb_service.shards import ShardedBM25Builder, ShardedBM25Searcher


def synthetic_corpus(n: int, seed: int) -> list[list[str]]:
    """Token lists with a Zipf-like vocabulary (a few very common terms, a long rare tail) and
    PubMed-like varying lengths, so shards differ in their local df and length statistics."""
    rng = random.Random(seed)
    vocab = [f"t{i}" for i in range(3000)]
    weights = [1.0 / (i + 1) for i in range(len(vocab))]
    docs = []
    for d in range(n):
        length = rng.randint(3, 40) if d % 7 else rng.randint(80, 200)  # some long documents
        docs.append(rng.choices(vocab, weights, k=length))
    return docs


def build_both(tmp_path, docs, shard_docs):
    single = BM25Builder()
    sharded = ShardedBM25Builder(tmp_path / "raw", shard_docs=shard_docs)
    for toks in docs:
        single.add(toks)
        sharded.add(toks)
    single.save(tmp_path / "single")
    info = sharded.save(tmp_path / "sharded")
    a = BM25Searcher(tmp_path / "single")
    s = ShardedBM25Searcher(tmp_path / "sharded")
    s.validate()
    return a, s, info


def assert_same(a, s, terms, k, mask=None):
    ids_a = a.term_ids(terms, MAX_QUERY_TERMS)
    ids_s = s.term_ids(terms, MAX_QUERY_TERMS)
    assert [t for t in terms if t in a.vocab] == [t for t in terms if s.df(t) > 0]
    names = {i: t for t, i in a.vocab.items()}
    assert ids_s == [names[i] for i in ids_a]  # the same selected terms, repeats and order included
    da, sa = a.search(ids_a, k, mask)
    ds, ss = s.search(ids_s, k, mask)
    assert da.tolist() == ds.tolist()  # same ids, same order
    np.testing.assert_allclose(ss, sa, rtol=0, atol=1e-6)
    assert ss.tolist() == sa.tolist()  # in fact bit-identical: the same weights summed in the same order
    return len(da)


def test_sharded_equals_single_index_on_seeded_corpus(tmp_path):
    docs = synthetic_corpus(3000, seed=11)
    a, s, info = build_both(tmp_path, docs, shard_docs=700)
    assert info["shards"] == 5 and info["num_docs"] == 3000 and len(s.shards) == 5
    assert [sh.num_docs for sh in s.shards] == [700, 700, 700, 700, 200]
    assert info["postings"] == len(a.data) and info["vocab"] == len(a.vocab)
    # Global statistics: every term's df summed over shards is the single index's column length.
    for t, j in list(a.vocab.items())[:500]:
        assert s.df(t) == int(a.indptr[j + 1] - a.indptr[j])
    rng = random.Random(5)
    vocab = list(a.vocab)
    mask = (np.arange(3000) % 4 != 1).astype(np.float32)
    nonempty = 0
    for trial in range(200):
        n_terms = rng.choice([1, 2, 3, 5, 40])  # 40 > MAX_QUERY_TERMS: the df-based cut must agree
        terms = [rng.choice(vocab) for _ in range(n_terms)] + (["unknown-term"] if trial % 5 == 0 else [])
        k = rng.choice([1, 5, 10, 100, 3000])
        nonempty += assert_same(a, s, terms, k, mask if trial % 3 == 0 else None) > 0
    assert nonempty == 200


def test_shard_local_statistics_would_differ(tmp_path):
    """The test above can fail: weights computed per shard with the shard's own N/df/avgdl give
    other scores, so the equality is due to the global statistics."""
    docs = synthetic_corpus(1500, seed=3)
    a, s, _ = build_both(tmp_path, docs, shard_docs=500)
    local = BM25Builder()
    for toks in docs[500:1000]:
        local.add(toks)
    local.save(tmp_path / "local")
    b = BM25Searcher(tmp_path / "local")
    t = next(t for t in b.vocab if s.df(t) > 3)
    _, s_local = b.search([b.vocab[t]], 5)
    shard = s.shards[1]
    _, s_global = shard.search([shard.vocab[t]], 5)
    assert not np.allclose(s_local, s_global, atol=1e-6)


def test_single_shard_and_ties(tmp_path):
    # Identical documents tie: the lower document number wins across shard boundaries too.
    docs = [["aspirin", "dose"]] * 10 + [["aspirin"]] * 3 + [["dose", "x"]] * 4
    a, s, info = build_both(tmp_path, docs, shard_docs=3)
    assert info["shards"] == 6
    for k in (1, 2, 4, 7, 17):
        assert_same(a, s, ["aspirin"], k)
        assert_same(a, s, ["dose", "aspirin"], k)
    a1, s1, info1 = build_both(tmp_path / "one", docs, shard_docs=1000)
    assert info1["shards"] == 1
    assert_same(a1, s1, ["aspirin", "x"], 10)


def test_sharded_manifest_checked(tmp_path):
    docs = synthetic_corpus(300, seed=1)
    _, s, _ = build_both(tmp_path, docs, shard_docs=100)
    meta = json.loads((tmp_path / "sharded" / "shards.json").read_text())
    meta["shards"][1]["num_docs"] = 99
    (tmp_path / "sharded" / "shards.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="shard-00001 holds 100 documents"):
        ShardedBM25Searcher(tmp_path / "sharded").validate()
    with pytest.raises(ValueError, match="shard_docs must be a positive integer"):
        ShardedBM25Builder(tmp_path / "raw", shard_docs=0)


def test_query_touching_every_document(tmp_path):
    """A query whose postings cover every document, then more postings of the same documents:
    the kernel's touched-list must hold one slot past the last document (it overran the heap)."""
    bm = BM25Builder()
    for _ in range(3):
        bm.add(["fever", "cough", "rash"])
    bm.save(tmp_path / "idx")
    a = BM25Searcher(tmp_path / "idx")
    for _ in range(50):
        docs, scores = a.search([a.vocab["fever"], a.vocab["cough"], a.vocab["rash"]], 3)
        assert docs.tolist() == [0, 1, 2] and len(set(scores.tolist())) == 1


def test_merge_orders_by_the_kernels_sums_not_the_scaled_scores(tmp_path):
    """Two different float32 sums can round to one value once multiplied by (k1 + 1); the single
    index ranks them by the sums, so the merge must too (seen once in 1,000 queries at 200K)."""
    from kb_service.engines import save_bm25s
    from kb_service.shards import SHARDS_FORMAT

    scale = np.float32(1.2 + 1.0)
    x = next(v for v in (np.float32(7.826296) + np.arange(2000, dtype=np.float32) * np.float32(1e-6))
             if v * scale == np.nextafter(v, np.float32(0)) * scale)
    y = np.nextafter(x, np.float32(0))  # y < x, y * scale == x * scale
    assert y < x and y * scale == x * scale

    def matrix(data):
        n = len(data)
        return {"data": np.asarray(data, np.float32), "indices": np.arange(n, dtype=np.int32),
                "indptr": np.array([0, n], np.int64), "num_docs": n}

    save_bm25s(tmp_path / "single", matrix([y, x]), {"t": 0}, 1.2, 0.75, "lucene")  # doc 1 has the larger sum
    for i, v in enumerate([y, x]):
        save_bm25s(tmp_path / "sharded" / f"shard-{i:05d}", matrix([v]), {"t": 0}, 1.2, 0.75, "lucene")
    (tmp_path / "sharded" / "shards.json").write_text(json.dumps({
        "format": SHARDS_FORMAT, "num_docs": 2, "shards": [{"dir": "shard-00000", "offset": 0, "num_docs": 1},
                                                           {"dir": "shard-00001", "offset": 1, "num_docs": 1}]}))
    a, s = BM25Searcher(tmp_path / "single"), ShardedBM25Searcher(tmp_path / "sharded")
    s.validate()
    da, sa = a.search([0], 2)
    ds, ss = s.search(["t"], 2)
    assert da.tolist() == [1, 0] and sa[0] == sa[1]  # equal scores, yet doc 1 first
    assert ds.tolist() == da.tolist() and ss.tolist() == sa.tolist()


def test_float32_mean_matches_numpy_reading_a_chunk_at_a_time(tmp_path):
    """The global average length, read from the shards' files in pieces, is numpy's own float32
    mean of all lengths (what BM25Builder uses), bit for bit, whatever the piece size."""
    from kb_service.shards import float32_mean, float32_sum

    rng = np.random.default_rng(0)
    # Fractional values: every partial sum rounds, so any other cut than numpy's shows.
    arrays = [(rng.random(n) * 600).astype(np.float32) for n in (1, 7, 130, 4099, 250_003, 1_000_000)]
    parts = []
    for i, a in enumerate(arrays):
        np.save(tmp_path / f"{i}.npy", a)
        parts.append((tmp_path / f"{i}.npy", len(a)))
    whole = np.concatenate(arrays)
    expect = float(whole.mean())
    for chunk in (1000, 65_536, 1 << 22):
        assert float32_sum(parts, chunk=chunk).tobytes() == np.add.reduce(whole).tobytes()
        assert float32_mean(parts, chunk=chunk) == expect
    # Not any sum of these: the obvious streaming sum (numpy's sum of each 65,536-value piece,
    # added in order) is another value, and so is its mean.
    blocked = np.float32(0)
    for i in range(0, len(whole), 65_536):
        blocked = np.float32(blocked + np.add.reduce(whole[i:i + 65_536]))
    assert blocked != np.add.reduce(whole) and float(np.float32(blocked / np.float32(len(whole)))) != expect


def test_terms_with_tabs_newlines_and_backslashes_merge_exactly(tmp_path):
    """The shards' sorted term lists are tab-separated lines: terms holding tabs, newlines or
    backslashes (escaped there) keep their own df and never merge with each other."""
    odd = ["a\tb", "a\\tb", "a\nb", "a\\nb", "a\\", "a", "\\", "\t", "x\r\ny", "\u00e9\u2028z"]
    docs = [[odd[(i * 3 + j) % len(odd)] for j in range(i % 5 + 1)] for i in range(60)]
    a, s, info = build_both(tmp_path, docs, shard_docs=7)
    assert info["vocab"] == len(a.vocab) == len(odd)
    for t in odd:
        assert s.df(t) == int(a.indptr[a.vocab[t] + 1] - a.indptr[a.vocab[t]]) > 0
        assert_same(a, s, [t], 10)
    assert_same(a, s, odd[:4], 60)


def test_memory_bound_cuts_shards_by_their_working_set(tmp_path, monkeypatch):
    """With `memory_bytes`, a shard ends when its estimated working set reaches the bound (here
    the per-posting estimate is raised so that a small corpus needs several shards): shards of
    varying sizes, results still exactly the single index's."""
    import kb_service.shards as shards

    monkeypatch.setattr(shards, "BYTES_PER_POSTING", 4000)
    docs = synthetic_corpus(2000, seed=4)
    single = BM25Builder()
    bounded = ShardedBM25Builder(tmp_path / "raw", shard_docs=10**9, memory_bytes=shards.MIN_MEMORY_BYTES)
    for toks in docs:
        single.add(toks)
        bounded.add(toks)
    single.save(tmp_path / "single")
    info = bounded.save(tmp_path / "sharded")
    a, s = BM25Searcher(tmp_path / "single"), ShardedBM25Searcher(tmp_path / "sharded")
    s.validate()
    sizes = [sh.num_docs for sh in s.shards]
    assert info["shards"] == len(sizes) >= 10 and len(set(sizes)) > 1 and sum(sizes) == 2000
    # Each shard stayed under the bound: postings * 4000 + vocabulary * BYTES_PER_TERM < 8 MiB,
    # but for the document that crossed it.
    for spec in s.meta["shards"][:-1]:
        assert 4000 * spec["postings"] + shards.BYTES_PER_TERM * spec["vocab"] < shards.MIN_MEMORY_BYTES + 4000 * 250
    rng = random.Random(8)
    vocab = list(a.vocab)
    for _ in range(100):
        assert_same(a, s, [rng.choice(vocab) for _ in range(rng.choice([1, 3, 8]))], rng.choice([1, 10, 50]))
    with pytest.raises(ValueError, match="memory_bytes must be an integer of at least"):
        ShardedBM25Builder(tmp_path / "raw2", memory_bytes=1000)
