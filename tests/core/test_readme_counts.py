"""The counts the README states are computed, not remembered: a new task, tool, instrument, safety
pattern or KB source that changes one fails here until the README says so."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")


def shipped_domains() -> list[str]:
    """The domains the project ships (tests/conftest.py also registers the ward test domain)."""
    from envs import registry

    return [d for d in registry.list_domains() if registry.DOMAINS[d].startswith("envs.")]


def stated(pattern: str) -> list[int]:
    """The integers the README's line matching `pattern` states (commas as thousands separators)."""
    match = re.search(pattern, README)
    assert match, f"README.md no longer has a line matching {pattern!r}"
    return [int(group.replace(",", "")) for group in match.groups()]


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def test_task_counts_per_split():
    from envs import registry

    total, train, test, validation = stated(
        r"\| tasks \| ([\d,]+) \(train ([\d,]+) / test ([\d,]+) / validation ([\d,]+)\)")
    domains = shipped_domains()
    assert len(domains) == 10
    assert sum(len(registry.get_tasks(d, None)) for d in domains) == total
    for split, count in (("train", train), ("test", test), ("validation", validation)):
        # a domain without the split (drug_interaction has no validation split) contributes none
        assert sum(len(registry.get_splits(d).get(split, [])) for d in domains) == count, split


def test_unique_tools_instruments_and_safety_patterns():
    from envs import registry
    from envs.calculators import CALCULATORS
    from envs.rewards import PATTERNS

    (tools,) = stated(r"\| tools \| ([\d,]+) unique tools")
    names = set()
    for domain in shipped_domains():
        names |= set(registry.get_environment(domain).toolkit.tool_names)
    assert len(names) == tools
    (instruments,) = stated(r"\| instruments \| ([\d,]+) validated clinical scores")
    assert len(CALCULATORS) == instruments
    patterns, levels = stated(r"safety \(([\d,]+) violation patterns over ([\d,]+) severity levels")
    assert len(PATTERNS) == patterns
    assert len({p.severity for p in PATTERNS.values()}) == levels


def test_knowledge_base_passages():
    from kb_service.kb import KnowledgeBase

    (passages,) = stated(r"\| knowledge base \| ([\d,]+) real passages")
    assert KnowledgeBase.open(warmup=False).stats()["n_passages"] == passages
