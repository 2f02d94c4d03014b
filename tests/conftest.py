"""Test-wide fixtures: the ward test domain is registered for every test session."""

from __future__ import annotations

import pytest

import envs  # noqa: F401  (runtime defaults, env registration)
from envs import registry
from tests.exit_guard import pytest_sessionfinish, pytest_unconfigure  # noqa: F401  (how the process ends)

registry.DOMAINS.setdefault("ward", "tests.fixtures.ward_domain.environment")


@pytest.fixture
def ward_env():
    from envs.env import HealthcareGymEnv

    env = HealthcareGymEnv(domain="ward", max_turns=6, render_mode="ansi")
    yield env
    env.close()
