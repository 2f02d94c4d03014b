"""The drug_interaction environment, shared by that domain's test modules (import `env` to use it)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def env():
    from envs.domains.drug_interaction.environment import get_environment

    try:
        return get_environment()
    except Exception as exc:  # the database is built by `hcgym data build`
        pytest.skip(f"drug_interaction database unavailable: {type(exc).__name__}: {exc}")
