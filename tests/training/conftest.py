"""Settings of the training tests. Their fixtures `ray_cluster` (one local Ray cluster per session)
and `ward_policy_dir` (a tiny policy built on the ward test domain: tokenizer trained on its corpus,
Qwen3 with hidden 64, 2 layers) are defined once in tests/conftest.py, so the evals, viewer and
cluster tests share the same instance.

Env processes of these tests run with HCGYM_EMBEDDINGS=0: free-text grading falls back to token
overlap instead of loading a sentence-embedding model into every process (about 16 s each)."""

from __future__ import annotations

import envs  # noqa: F401  (CPU runtime defaults before torch/ray load)

NO_EMBEDDINGS = {"HCGYM_EMBEDDINGS": "0"}


# The session cluster's `envs._runtime.init_ray` arguments (test_placement.py restarts it after its
# own multi-node cluster).
# "local": a fresh cluster even while a `ray start --head` (tests/cluster, a user) runs on this machine.
SESSION_RAY_INIT = {"address": "local", "num_cpus": 2, "include_dashboard": False, "namespace": "hcgym-tests", "log_to_driver": False}
