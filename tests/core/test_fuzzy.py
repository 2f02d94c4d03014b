"""`envs.core.fuzzy`: indexed suggestions equal `difflib.get_close_matches`."""

from __future__ import annotations

import difflib
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.core.fuzzy import FuzzyIndex, PrefixIndex, _LcsBound, close_matches, names_starting_with


def typo(rng: random.Random, name: str, edits: int) -> str:
    chars = list(name)
    for _ in range(edits):
        op, at = rng.randrange(3), rng.randrange(len(chars) + 1)
        if op == 0 or not chars:
            chars.insert(at, rng.choice("abcdefghijklmnopqrstuvwxyz -"))
        elif op == 1:
            chars.pop(min(at, len(chars) - 1))
        else:
            chars[min(at, len(chars) - 1)] = rng.choice("aeiouy")
    return "".join(chars)


def generated_names(rng: random.Random, count: int) -> list[str]:
    """Drug-like names built from common stems (not a copy of any formulary)."""
    stems = ["amlo", "ator", "warf", "meto", "cipro", "flu", "clopi", "enal", "lisin", "sim", "para", "ibu",
             "dox", "levo", "carba", "val", "pro", "tri", "sulfa", "dig"]
    tails = ["dipine", "vastatin", "arin", "prolol", "floxacin", "oxetine", "dogrel", "april", "opril", "cetamol",
             "profen", "ycycline", "thyroxine", "mazepine", "sartan", "pranolol", "methoprim", "oxin", " sodium", ""]
    names = {rng.choice(stems) + rng.choice(tails) + rng.choice(["", "", "e", "é", " 5 mg", "-xr"]) for _ in range(count)}
    return sorted(names, key=lambda _: rng.random())


@pytest.mark.parametrize("n,cutoff", [(5, 0.75), (3, 0.6), (1, 0.0), (10, 0.9), (2, 1.0)])
def test_suggestions_equal_difflib_on_typos_and_unknown_names(n, cutoff):
    rng = random.Random(f"fuzzy-{n}-{cutoff}")
    names = generated_names(rng, 400)
    index = FuzzyIndex(names)
    queries = [typo(rng, rng.choice(names), rng.randint(0, 4)) for _ in range(150)]
    queries += ["", "a", "zq0001xkv", "x" * 300, "é", names[0], names[0].upper(), "amlodipine" * 30]
    for query in queries:
        assert index.close_matches(query, n=n, cutoff=cutoff) == difflib.get_close_matches(query, names, n, cutoff), query


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(names=st.lists(st.text(alphabet="abcab é-", max_size=9), max_size=25), query=st.text(alphabet="abcxé-", max_size=10),
       n=st.integers(1, 4), cutoff=st.sampled_from([0.0, 0.3, 0.5, 0.6, 2 / 3, 0.75, 0.8, 1.0]))
def test_suggestions_equal_difflib_property(names, query, n, cutoff):
    # small alphabets make ties, duplicates, empty names and exact-cutoff ratios common
    assert FuzzyIndex(names).close_matches(query, n=n, cutoff=cutoff) == difflib.get_close_matches(query, names, n, cutoff)


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(a=st.text(alphabet="abcd", max_size=12), b=st.text(alphabet="abcd", max_size=12))
def test_lcs_bound_is_the_longest_common_subsequence(a, b):
    table = [[0] * (len(b) + 1) for _ in range(len(a) + 1)]
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            table[i + 1][j + 1] = table[i][j] + 1 if x == y else max(table[i][j + 1], table[i + 1][j])
    assert _LcsBound(a).length(b) == table[len(a)][len(b)]


def test_drug_formulary_suggestions_equal_difflib():
    from envs.domains.drug_interaction.environment import load_db

    names = load_db().name_index
    rng = random.Random("formulary")
    queries = [typo(rng, rng.choice(list(names)), rng.randint(1, 3)) for _ in range(40)] + ["zq0001xkv", "asprin"]
    for query in queries:
        assert close_matches(query, names, n=5, cutoff=0.75) == difflib.get_close_matches(query, list(names), 5, 0.75)


def test_index_is_built_once_per_collection_and_rebuilt_when_it_grows():
    names = {"warfarin": "d1", "aspirin": "d2"}
    first = FuzzyIndex.for_names(names)
    assert FuzzyIndex.for_names(names) is first
    assert FuzzyIndex.for_names(dict(names)) is not first  # another object, another index
    names["heparin"] = "d3"
    grown = FuzzyIndex.for_names(names)
    assert grown is not first and close_matches("heparn", names, n=1) == ["heparin"]


def test_bad_arguments_are_named():
    index = FuzzyIndex(["a"])
    with pytest.raises(ValueError, match="n must be > 0"):
        index.close_matches("a", n=0)
    with pytest.raises(ValueError, match=r"cutoff must be in \[0.0, 1.0\]"):
        index.close_matches("a", cutoff=1.5)
    with pytest.raises(TypeError, match="word must be a str, got int"):
        index.close_matches(5)
    with pytest.raises(TypeError, match="name at position 1 is int"):
        FuzzyIndex(["a", 3])


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(names=st.lists(st.text(alphabet="abc é", max_size=6), max_size=40), prefix=st.text(alphabet="abc é", max_size=3),
       limit=st.integers(1, 10))
def test_prefix_suggestions_equal_the_sorted_scan(names, prefix, limit):
    expected = sorted({n for n in names if n.startswith(prefix)})[:limit]
    assert PrefixIndex(names).starting_with(prefix, limit) == expected
    assert names_starting_with(prefix, {n: 1 for n in names}, limit) == expected


def test_medical_qa_unknown_names_get_prefix_suggestions():
    from envs.env import HealthcareGymEnv

    env = HealthcareGymEnv(domain="medical_qa")
    env.reset(seed=0)
    kb = env.domain_env.toolkit.toolkits[0].kb
    outcome = env.domain_env.toolkit.call("lookup_hpo_term", {"term": "seizzzz"})
    expected = sorted({n for n in kb.term_by_name if n.startswith("seiz")})[:8]
    assert expected and outcome.error_kind == "tool_error"
    assert f"similar names: {', '.join(expected)}" in outcome.error
