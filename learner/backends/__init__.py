"""Learner backends: where the policy's forward/backward/optimizer step run.

`torch` (single process) and `deepspeed` (ZeRO-3, one or more ranks). Both implement
`LearnerBackend` (base.py); the loss and the batch logic live in `worker.py` and are shared.
How to add one: learner/README.md.
"""

from learner.backends.base import LearnerBackend
from learner.backends.factory import make_backend

__all__ = ["LearnerBackend", "make_backend"]
