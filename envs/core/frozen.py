"""Large read-only indexes (ICD-10-CM, HPO, lab catalogue) loaded once per process and moved out of
the garbage collector's scans."""

from __future__ import annotations

import atexit
import gc
from typing import TypeVar

T = TypeVar("T")
_UNFREEZE_REGISTERED = False


def frozen(obj: T) -> T:
    """Move the freshly loaded (large, immutable) index out of the garbage collector's scans, so
    later allocations in tools and resets do not pay for traversing millions of objects. At exit the
    objects are handed back to the collector, so extension modules loaded before the freeze (duckdb)
    see their objects released instead of reporting leaks."""
    gc.collect()
    gc.freeze()
    global _UNFREEZE_REGISTERED
    if not _UNFREEZE_REGISTERED:
        atexit.register(gc.unfreeze)
        _UNFREEZE_REGISTERED = True
    return obj
