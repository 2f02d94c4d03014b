"""Test-wide fixtures: the ward test domain is registered for every test session; the session's
local Ray cluster and tiny ward policy are defined here once, so every package that uses them
(training, evals, viewer, cluster) shares one instance. A fixture imported into another conftest or
test module would be a second definition, built again for that module."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

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


@pytest.fixture(scope="session")
def ray_cluster():
    """A local 2-CPU cluster on loopback once per test session (about 5 s), shut down at the end."""
    import ray

    from envs._runtime import init_ray
    from tests.training.conftest import SESSION_RAY_INIT

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


@pytest.fixture(scope="session")
def ttopd_store_run(ray_cluster, ward_policy_dir, tmp_path_factory) -> Path:
    """A 3-step TT-OPD run on the ward domain (weights and teacher updates through the object store,
    staleness 0, a validation pass at the start): the run folder `hcgym train` writes, teacher hints
    and log-probs included. tests/training/test_train.py compares it with the same run over the
    collective group, and the viewer tests serve it; one run costs about 10 s on 2 cores."""
    from actors.env_actor import register_domains
    from learner.train import train
    from tests.training.test_train import STORE_VS_GROUP_STEPS, ttopd_config

    run_dir = tmp_path_factory.mktemp("ttopd_store_run") / "store"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("HCGYM_EMBEDDINGS", "0")
        register_domains({"ward": "tests.fixtures.ward_domain.environment"})
        train(ttopd_config(run_dir, ward_policy_dir, trainer=STORE_VS_GROUP_STEPS), log=lambda line: None)
    return run_dir
