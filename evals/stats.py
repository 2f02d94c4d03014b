"""Statistics a reviewer accepts: bootstrap confidence intervals, paired bootstrap, exact McNemar.

Plain functions over numpy arrays; nothing here knows about result rows (see `evals.metrics`).

* `bootstrap_ci(values)`: percentile bootstrap 95% CI of the mean. Items are resampled with
  replacement `n_resamples` times (one vectorised draw of indices, seeded), the 2.5th and 97.5th
  percentiles of the resampled means are the interval.
* `paired_bootstrap_ci(a, b)`: the same over per-item differences a_i - b_i of two policies on the
  same items: resampling items (not the two arms independently) keeps the pairing, which is what
  makes the interval narrow when both policies find the same items hard.
* `mcnemar_exact(a_correct, b_correct)`: the exact (binomial) McNemar test on discordant pairs:
  under H0 the n = b + c discordant items split Binomial(n, 1/2); the two-sided p-value is
  min(1, 2 * P(X <= min(b, c))). Exact rather than the chi-square approximation because benchmark
  subsets are often small and discordant counts of a handful are common.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

DEFAULT_RESAMPLES = 10_000
DEFAULT_SEED = 0
# Bound the (n_resamples x n_items) index matrix (8 bytes a cell) so large benchmarks stay near 32 MB:
# resampling is done in chunks of at most this many cells.
_MAX_CELLS = 4_000_000


@dataclass(frozen=True)
class Interval:
    """A point estimate with its confidence interval over `n` items."""

    estimate: float
    low: float
    high: float
    n: int

    def as_dict(self) -> dict[str, float | int]:
        return {"estimate": self.estimate, "low": self.low, "high": self.high, "n": self.n}


@dataclass(frozen=True)
class McNemarResult:
    """Discordant counts and the exact two-sided p-value.

    `a_only`: items A got right and B wrong; `b_only`: the reverse; `both`/`neither`: concordant.
    """

    a_only: int
    b_only: int
    both: int
    neither: int
    p_value: float

    @property
    def n(self) -> int:
        return self.a_only + self.b_only + self.both + self.neither


def _as_vector(values: Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D sequence of numbers, got shape {array.shape}")
    if array.size and not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return array


def _check_params(confidence: float, n_resamples: int) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if n_resamples < 1:
        raise ValueError(f"n_resamples must be >= 1, got {n_resamples}")


def bootstrap_means(values: np.ndarray, *, n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> np.ndarray:
    """Means of `n_resamples` resamples (with replacement) of `values`; deterministic for a seed."""
    n = values.size
    rng = np.random.default_rng(seed)
    chunk = max(1, _MAX_CELLS // max(n, 1))
    means = np.empty(n_resamples, dtype=float)
    for start in range(0, n_resamples, chunk):
        stop = min(n_resamples, start + chunk)
        idx = rng.integers(0, n, size=(stop - start, n))
        means[start:stop] = values[idx].mean(axis=1)
    return means


def bootstrap_ci(values: Sequence[float] | np.ndarray, *, confidence: float = 0.95,
                 n_resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED) -> Interval:
    """Percentile bootstrap CI of the mean of `values` (one value per item)."""
    _check_params(confidence, n_resamples)
    array = _as_vector(values, "values")
    if array.size == 0:
        raise ValueError("values: no items to compute a confidence interval over")
    estimate = float(array.mean())
    if array.size == 1 or np.all(array == array[0]):
        return Interval(estimate, estimate, estimate, int(array.size))  # no spread to resample
    means = bootstrap_means(array, n_resamples=n_resamples, seed=seed)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [alpha, 1.0 - alpha])
    return Interval(estimate, float(low), float(high), int(array.size))


def paired_bootstrap_ci(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray, *,
                        confidence: float = 0.95, n_resamples: int = DEFAULT_RESAMPLES,
                        seed: int = DEFAULT_SEED) -> Interval:
    """CI of mean(a - b) over shared items, resampling items jointly (a[i] and b[i] are one item)."""
    left, right = _as_vector(a, "a"), _as_vector(b, "b")
    if left.shape != right.shape:
        raise ValueError(f"paired samples must have the same length: a has {left.size}, b has {right.size}")
    return bootstrap_ci(left - right, confidence=confidence, n_resamples=n_resamples, seed=seed)


def binomial_cdf_half(k: int, n: int) -> float:
    """P(X <= k) for X ~ Binomial(n, 1/2), exactly (integer arithmetic, then one division)."""
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    return sum(math.comb(n, i) for i in range(k + 1)) / 2**n


def mcnemar_exact(a_correct: Sequence[bool] | np.ndarray, b_correct: Sequence[bool] | np.ndarray) -> McNemarResult:
    """Exact McNemar test of two policies' correctness on the same items (two-sided)."""
    left = np.asarray(a_correct)
    right = np.asarray(b_correct)
    if left.shape != right.shape or left.ndim != 1:
        raise ValueError(f"paired correctness vectors must be 1-D and of equal length: {left.shape} vs {right.shape}")
    for name, array in (("a_correct", left), ("b_correct", right)):
        if array.size and not np.isin(array, [0, 1, True, False]).all():
            raise ValueError(f"{name}: correctness must be boolean (or 0/1)")
    left, right = left.astype(bool), right.astype(bool)
    a_only = int(np.sum(left & ~right))
    b_only = int(np.sum(~left & right))
    discordant = a_only + b_only
    p_value = 1.0 if discordant == 0 else min(1.0, 2.0 * binomial_cdf_half(min(a_only, b_only), discordant))
    return McNemarResult(a_only=a_only, b_only=b_only, both=int(np.sum(left & right)),
                         neither=int(np.sum(~left & ~right)), p_value=p_value)


__all__ = [
    "DEFAULT_RESAMPLES",
    "Interval",
    "McNemarResult",
    "binomial_cdf_half",
    "bootstrap_ci",
    "bootstrap_means",
    "mcnemar_exact",
    "paired_bootstrap_ci",
]
