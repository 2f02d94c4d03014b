"""What a process does before its first transformers import that reaches a tokenizer or a model:
no per-shard progress bars, and no scikit-learn import.

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
    """Call before importing transformers' tokenizers or models (idempotent). Also turns off
    transformers' per-shard progress bars: the driver prints one progress line per step instead."""
    import transformers.utils
    from transformers.utils import logging as hf_logging

    hf_logging.disable_progress_bar()
    # Once the generation module is loaded its probe has run: nothing left to skip.
    if "transformers.generation" not in sys.modules:
        transformers.utils.is_sklearn_available = _sklearn_left_out
