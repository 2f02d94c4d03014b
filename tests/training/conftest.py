"""Fixtures of the training tests: one local Ray cluster per session, and a tiny policy built on
the ward test domain (tokenizer trained on its corpus, Qwen3 with hidden 64, 2 layers).

Env processes of these tests run with HCGYM_EMBEDDINGS=0: free-text grading falls back to token
overlap instead of loading a sentence-embedding model into every process (about 16 s each)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

import envs  # noqa: F401  (CPU runtime defaults before torch/ray load)

NO_EMBEDDINGS = {"HCGYM_EMBEDDINGS": "0"}


# The session cluster's `envs._runtime.init_ray` arguments (test_placement.py restarts it after its
# own multi-node cluster).
# "local": a fresh cluster even while a `ray start --head` (tests/cluster, a user) runs on this machine.
SESSION_RAY_INIT = {"address": "local", "num_cpus": 2, "include_dashboard": False, "namespace": "hcgym-tests", "log_to_driver": False}


@pytest.fixture(scope="session")
def ray_cluster():
    """A local 2-CPU cluster on loopback once per test session (about 5 s), shut down at the end."""
    import ray

    from envs._runtime import init_ray

    started = False
    if not ray.is_initialized():
        init_ray(**SESSION_RAY_INIT)
        started = True
    yield ray
    if started:
        ray.shutdown()


@pytest.fixture(scope="session")
def ward_policy_dir() -> str:
    """A tiny ChatML policy whose tokenizer was trained on the ward domain's corpus (built once)."""
    from modeling.model import build_tiny_model, train_tokenizer
    from learner.sft import task_corpus

    root = Path(tempfile.mkdtemp(prefix="t2_ward_policy_"))
    # Gold replays grade free text; token overlap is enough here (no sentence-embedding model load).
    previous = os.environ.get("HCGYM_EMBEDDINGS")
    os.environ["HCGYM_EMBEDDINGS"] = "0"
    try:
        corpus = task_corpus(["ward"], None) * 20
    finally:
        if previous is None:
            os.environ.pop("HCGYM_EMBEDDINGS")
        else:
            os.environ["HCGYM_EMBEDDINGS"] = previous
    tok = train_tokenizer(corpus, 1024, root / "tok", max_stdlib_files=40)
    out = build_tiny_model(root / "model", tok, seed=0, hidden_size=64, intermediate_size=128, num_hidden_layers=2,
                           num_attention_heads=4, num_key_value_heads=2, head_dim=16)
    return str(out)
