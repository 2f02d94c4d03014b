"""Any text is a valid query: never an exception, always a list (maybe empty) of passages."""

from __future__ import annotations

import string

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kb_service.analysis import plan_query
from kb_service.schema import Passage

SYNTAX = ['"', "'", "(", ")", "-", "+", "*", ":", "^", "~", "[", "]", "{", "}", "\\", "/", "?", "<", ">", "!",
          "&&", "||", " AND ", " OR ", " NOT ", " NEAR ", "NEAR(", "title:", "content:", "source:", " TO ", "\x00",
          "\n", "\t", "\u2028", "😀", "🩺", "日本語", "Ελληνικά", "العربية", "\ud800", "é", "ß", "İ"]
WORDS = ["heart", "failure", "asthma", "warfarin", "pheochromocytoma", "cough", "covid-19", "the", "of", "x"]

# A byte string picks tokens from this table (one cheap draw per query), mixing query syntax,
# real words, scripts, emoji and control characters in any order; plus arbitrary unicode text.
TOKENS = SYNTAX + WORDS + list(string.printable) + [" "] * 20
TOKENS = (TOKENS * (256 // len(TOKENS) + 1))[:256]


def _tokens(raw: bytes, sep: str) -> str:
    return sep.join(TOKENS[b] for b in raw)


queries = st.one_of(
    st.text(max_size=200),
    st.binary(max_size=60).map(lambda raw: _tokens(raw, "")),
    st.binary(max_size=40).map(lambda raw: _tokens(raw, " ")),
)


def assert_valid_results(results, k):
    assert isinstance(results, list) and len(results) <= k
    assert all(isinstance(r, Passage) and r.doc_id and r.score > 0 for r in results)
    scores = [r.score for r in results]
    assert scores == sorted(scores, reverse=True)


@settings(max_examples=10_000, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(q=queries, k=st.integers(min_value=0, max_value=30), filt=st.sampled_from([None, "wiki", ["drugs", "wiki"]]))
def test_any_query_is_valid(kb, q, k, filt):
    results = kb.search(q, k=k, source=filt)
    assert_valid_results(results, k)


NASTY = [
    "", " ", "\n\t", '"', '""', '"""', "(", ")", ")(", "((((((((((", "-", "+", "--", "-+-", "*", "**", ":", "::",
    "AND", "OR", "NOT", "AND OR NOT", "NOT NOT NOT heart", "heart AND", "AND heart", "heart OR OR asthma",
    "NEAR(heart failure, 5)", "heart NEAR failure", "hea*", "title:heart", "source:wiki heart", "heart^2",
    "heart~1", "[a TO z]", "{a TO z}", "a:b:c", "'single quotes'", 'unbalanced "phrase', "emoji 😀🩺",
    "日本語の検索", "\ud800 lone surrogate", "\x00 nul", "x" * 100_000, ("heart failure " * 8_000),
    "(" * 5_000 + "asthma" + ")" * 5_000, "NOT " * 10_000 + "asthma", '"' * 9_999, "- " * 20_000,
]


def test_nasty_queries(kb):
    for q in NASTY:
        assert_valid_results(kb.search(q, k=10), 10)
    assert kb.search("(" * 5_000 + "asthma" + ")" * 5_000, k=3)  # absurd nesting still finds asthma
    assert kb.search("x" * 100_000) == []


def test_non_string_inputs(kb):
    for q in (None, 42, 3.5, b"bytes", ["heart"], {"q": 1}):
        assert_valid_results(kb.search(q, k=5), 5)  # type: ignore[arg-type]


@settings(max_examples=300, deadline=None, derandomize=True)
@given(q=queries)
def test_planner_is_total(q):
    plan = plan_query(q)
    assert plan.kind in ("empty", "free", "structured")
