"""Adapters from our calculators' arguments to independent open-source implementations.

Adapters live in one module per peer (``peers_medcalc.py``, ``peers_open_medicine.py`` and, for
the AGPL one, ``peers_clincalc.py``); this module re-exports the first two. Each adapter takes
*our* keyword arguments and returns the peer's numeric score, so a property test can compare
``ours(**kw).score`` with ``peer(**kw)``. Peers used (test-only dependencies):

* ``medcalc`` (medcalc-bench 1.7.0, Apache-2.0): functions take ``{name: (value, unit)}`` dicts
  and return ``{"Explanation": ..., "Answer": ...}``;
* ``open_medicine`` (0.12.0, MIT): pydantic ``*Params`` models, results in ``.value``;
* ``clincalc`` (0.4.0, AGPL-3.0): adapters in ``peers_clincalc.py``, kept apart so that this
  module (used by ``bench/calculators.py`` too) never imports AGPL code; clincalc is imported
  by tests only, never from ``envs/`` or ``bench/``.

Where a peer's definition differs from the published one, the adapter does not paper over it:
the property test restricts or special-cases the inputs and says why.
"""

from __future__ import annotations

from .peers_common import _DVT_KEYS, _NIHSS_OURS, _trop_points  # noqa: F401
from .peers_medcalc import *  # noqa: F401,F403
from .peers_open_medicine import *  # noqa: F401,F403
