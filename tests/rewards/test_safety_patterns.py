"""Every catalogued safety pattern is triggered by a concrete trajectory, at its severity."""

from __future__ import annotations

import pytest

from envs.rewards import PATTERNS, detect_violations, score_episode
from envs.rewards.safety_patterns import patterns_by_severity
from tests.rewards.safety_cases import CASES


def test_catalogue_size_and_shape():
    by_sev = {s: len(p) for s, p in patterns_by_severity().items()}
    assert sum(by_sev.values()) == len(PATTERNS) >= 50
    assert all(by_sev[s] >= 5 for s in (1, 2, 3, 4, 5))
    assert {p.principle for p in PATTERNS.values()} == {"nonmaleficence", "beneficence", "autonomy", "justice"}


def test_every_pattern_has_a_case():
    assert sorted(set(PATTERNS) - set(CASES)) == []


@pytest.mark.parametrize("pattern_id", sorted(PATTERNS))
def test_pattern_is_detected(pattern_id):
    trajectory, task, context = CASES[pattern_id]()
    violations, errors = detect_violations(trajectory, task, context)
    found = {v.pattern_id: v for v in violations}
    assert pattern_id in found, f"expected {pattern_id}, got {sorted(found)}"
    assert errors == []
    violation = found[pattern_id]
    pattern = PATTERNS[pattern_id]
    assert (violation.severity, violation.category, violation.principle) == (pattern.severity, pattern.category, pattern.principle)
    assert violation.evidence
    # the breakdown carries it and the total is penalised accordingly
    breakdown = score_episode(trajectory, task, context=context)
    assert pattern_id in {v.pattern_id for v in breakdown.violations}
    if pattern.severity == 5:
        assert breakdown.total <= 0.1 + 1e-12 and breakdown.capped
    else:
        assert breakdown.total <= breakdown.base_total - 0.01 + 1e-9


def test_docs_list_every_pattern():
    from pathlib import Path

    from envs.rewards.safety_patterns import markdown_table

    docs = (Path(__file__).resolve().parents[2] / "docs" / "rewards.md").read_text(encoding="utf-8")
    assert markdown_table() in docs, "regenerate the table: python -c 'from envs.rewards.safety_patterns import markdown_table; print(markdown_table())'"


def test_every_pattern_names_its_source():
    """Each pattern names the guideline, label section or standard it follows, and
    a pattern registered without one is refused (naming the pattern)."""
    from envs.rewards import Pattern, register_pattern
    from envs.rewards.safety_patterns import EMERGENCY_SOURCES, EMERGENCY_TYPES

    missing = sorted(p.id for p in PATTERNS.values() if len(p.source.strip()) < 12)
    assert missing == []
    assert set(EMERGENCY_SOURCES) == set(EMERGENCY_TYPES)
    # the pathway patterns cite the guideline that sets their time targets
    assert "door-to-balloon" in PATTERNS["missed_emergency.stemi"].source
    assert "Surviving Sepsis" in PATTERNS["missed_emergency.sepsis"].source
    with pytest.raises(ValueError, match="demo.unsourced.*source"):
        register_pattern(Pattern("demo.unsourced", 2, "style", "justice", "a pattern with no source", " "))
    assert "demo.unsourced" not in PATTERNS
