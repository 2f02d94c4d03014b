"""What a process does before its first transformers import that reaches a tokenizer or a model.

transformers' generation module (reached by `AutoTokenizer`, `AutoConfig`, every model class)
imports `sklearn.metrics.roc_curve` whenever scikit-learn is installed
(`generation/candidate_generator.py`), for one feature: the confidence threshold of assisted
decoding, which nothing here uses. That import is about a second of CPU in every process that loads a
tokenizer or a model (the driver, each learner rank, generator and teacher; the test suite starts
about a hundred), and scikit-learn is installed only because sentence-transformers depends on it (it
imports scikit-learn itself when used). `prepare_transformers` reports scikit-learn absent to
transformers before its generation module loads, so that import is skipped; assisted decoding with
a confidence threshold in the same process would raise transformers' own "requires scikit-learn" error.
"""

from __future__ import annotations

import sys


def _sklearn_left_out() -> bool:
    return False


def prepare_transformers() -> None:
    """Call before importing transformers' tokenizers or models (idempotent; does nothing once
    transformers' generation module is loaded, as the probe has then run)."""
    if "transformers.generation" in sys.modules:
        return
    import transformers.utils

    transformers.utils.is_sklearn_available = _sklearn_left_out
