"""Reward tests grade without the embedding model unless a test installs one."""

from __future__ import annotations

import pytest

from envs.rewards import similarity


@pytest.fixture(autouse=True)
def _no_embeddings():
    """Unit tests grade without the embedding model (deterministic, fast); the embedding tests
    install the real model or a fake explicitly."""
    similarity.set_embedder(None, status="disabled (tests)")
    yield
    similarity.set_embedder(None, status="disabled (tests)")
