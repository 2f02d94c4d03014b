"""`TermLookup`, the compact bm25s vocabulary a loaded index searches with: the same columns as
bm25s's dict for every term, None for terms it lacks, exact under hash collisions, and about
30 bytes a term."""

from __future__ import annotations

import random

import pytest

import kb_service.engines as engines
from kb_service.engines import TermLookup


def _vocab(n: int, seed: int = 0) -> dict[str, int]:
    rng = random.Random(seed)
    stems = ["myocard", "infarct", "troponin", "β-lact", "naïv", "µg", "café", "x"]
    terms = {f"{rng.choice(stems)}{i}{'é' * (i % 3)}" for i in range(n)}
    return {t: j for j, t in enumerate(sorted(terms, key=lambda _t: rng.random()))}


def test_every_term_maps_to_its_column_and_others_to_none():
    vocab = _vocab(5000)
    lookup = TermLookup(vocab)
    assert len(lookup) == len(vocab)
    terms = list(vocab)
    assert lookup.columns(terms) == [vocab[t] for t in terms]
    assert all(lookup[t] == j and t in lookup and lookup.get(t) == j for t, j in list(vocab.items())[:500])
    missing = ["troponin", "", "myocard0é", "Troponin1", "x" * 300]
    assert lookup.columns(missing) == [None] * len(missing)
    assert not any(t in lookup for t in missing) and lookup.get("troponin") is None
    with pytest.raises(KeyError):
        lookup["troponin"]
    assert 12345 not in lookup
    # Iteration and items in column order, as the dict bm25s wrote: equal as a mapping.
    assert list(lookup) == sorted(vocab, key=vocab.__getitem__)
    assert dict(lookup.items()) == vocab and lookup == vocab
    assert lookup.columns([]) == [] and TermLookup({}).columns(["a"]) == [None]


def test_colliding_hashes_still_find_the_exact_term(monkeypatch):
    # Every term hashes to one of 3 values: each lookup must walk its run and compare bytes.
    monkeypatch.setattr(engines, "hash", lambda term: len(term) % 3, raising=False)
    vocab = _vocab(2000, seed=1)
    lookup = TermLookup(vocab)
    terms = list(vocab)
    assert lookup.columns(terms) == [vocab[t] for t in terms]
    assert lookup.columns(["absent-term", "naïv"]) == [None, None]


def test_it_holds_about_thirty_bytes_a_term():
    vocab = _vocab(200_000, seed=2)
    lookup = TermLookup(vocab)
    held = lookup._hashes.nbytes + lookup._columns.nbytes + lookup._offsets.nbytes + len(lookup._blob)
    text = sum(len(t.encode("utf-8")) for t in vocab)
    assert held <= text + 21 * len(vocab), (held, text, len(vocab))


def test_columns_that_are_not_a_permutation_are_refused():
    with pytest.raises(ValueError, match=r"columns are not 0..1 \(term 'b' has 5\)"):
        TermLookup({"a": 0, "b": 5})
    with pytest.raises(ValueError, match=r"term 'b' has 0"):
        TermLookup({"a": 0, "b": 0})
