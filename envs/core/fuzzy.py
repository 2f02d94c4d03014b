"""Fuzzy "did you mean" suggestions from an index: the same answers as `difflib.get_close_matches`,
without scoring every name per call.

`difflib.get_close_matches(word, names, n, cutoff)` keeps a name only if three ratios all reach the
cutoff: `real_quick_ratio` (from the two lengths), `quick_ratio` (2 * the size of the multiset
intersection of the two strings' characters / the total length) and `ratio` (the real matching).
The first two are upper bounds of the third, so they are necessary conditions. Over 11,000 drug
names difflib computes them name by name in Python: ~10 ms per unknown name, and an action of
thousands of lookups of unknown names takes tens of seconds (docs/benchmarks.md, "A hostile
action's cost").

`FuzzyIndex` keeps a name-by-character count matrix. Per query it computes `quick_ratio` for all
names at once (numpy, only over the query's own characters), keeps the names whose lengths and
character overlap can reach the cutoff, and runs difflib's own three checks and ranking on those
few. Since the pruning drops only names difflib itself would reject at `quick_ratio`, the
suggestions are exactly difflib's, in difflib's order (ties included).

Use `FuzzyIndex.for_names(collection)` (or `close_matches`) for a read-only name collection that
lives across calls (a database's name index): the index is built once per collection object and
reused. `PrefixIndex` does the same for "names starting with" suggestions (a binary search over
the sorted names instead of a scan).
"""

from __future__ import annotations

import bisect
import difflib
import heapq
import threading
from collections import Counter, OrderedDict
from typing import Any, Iterable

import numpy as np

_COUNT_DTYPE = np.int32


class FuzzyIndex:
    """Close-match suggestions over a fixed list of names (equal to `difflib.get_close_matches`).

    Args:
        names: The candidate names (any iterable of str; order is kept, duplicates are kept as
            difflib would keep them).
    """

    def __init__(self, names: Iterable[str]) -> None:
        self.names: list[str] = [name for name in names]
        for position, name in enumerate(self.names):
            if not isinstance(name, str):
                raise TypeError(f"FuzzyIndex: name at position {position} is {type(name).__name__}, expected str")
        alphabet = sorted({ch for name in self.names for ch in name})
        self._column = {ch: i for i, ch in enumerate(alphabet)}
        # Column-major: a query reads only the columns of its own characters.
        counts = np.zeros((len(self.names), len(alphabet)), dtype=_COUNT_DTYPE, order="F")
        for row, name in enumerate(self.names):
            for ch, count in Counter(name).items():
                counts[row, self._column[ch]] = count
        self._counts = counts
        self._lengths = np.fromiter((len(name) for name in self.names), dtype=np.int64, count=len(self.names))

    def __len__(self) -> int:
        return len(self.names)

    def candidates(self, word: str, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
        """(row numbers, quick_ratio bounds) of the names whose `real_quick_ratio` and
        `quick_ratio` against `word` reach `cutoff`, best bound first. A superset, by a float
        margin, of the names difflib keeps; the bounds are computed as difflib computes them."""
        empty = (np.zeros(0, dtype=np.int64), np.zeros(0))
        if not self.names:
            return empty
        total = self._lengths + len(word)
        margin = 1e-9  # float rounding must never prune a name difflib keeps; the ratio is checked exactly
        # real_quick_ratio: 2 * min(len) / total
        possible = 2.0 * np.minimum(self._lengths, len(word)) >= (cutoff - margin) * total
        if not possible.any():  # e.g. a 10,000-character "name": no length can reach the cutoff
            return empty
        # quick_ratio: 2 * the characters the two strings share (as multisets) / total
        shared = np.zeros(len(self.names), dtype=np.int64)
        for ch, count in Counter(word).items():
            column = self._column.get(ch)
            if column is not None:
                shared += np.minimum(self._counts[:, column], count)
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(total > 0, 2.0 * shared / np.maximum(total, 1), 1.0)
        rows = np.flatnonzero(possible & (bound >= cutoff - margin))
        order = np.argsort(-bound[rows], kind="stable")
        return rows[order], bound[rows][order]

    def close_matches(self, word: str, n: int = 3, cutoff: float = 0.6) -> list[str]:
        """The best "good enough" matches of `word`, exactly as `difflib.get_close_matches(word,
        names, n, cutoff)` returns them.

        Raises:
            ValueError: n <= 0 or cutoff outside [0, 1] (difflib's own checks).
            TypeError: word is not a str.
        """
        if not n > 0:
            raise ValueError(f"n must be > 0: {n!r}")
        if not 0.0 <= cutoff <= 1.0:
            raise ValueError(f"cutoff must be in [0.0, 1.0]: {cutoff!r}")
        if not isinstance(word, str):
            raise TypeError(f"word must be a str, got {type(word).__name__}")
        best: list[tuple[float, str]] = []  # a min-heap of the n best (ratio, name) so far
        rows, bounds = self.candidates(word, cutoff)
        if not len(rows):  # e.g. a 100,000-character "name": nothing can match, nothing more to build
            return []
        matcher = difflib.SequenceMatcher()
        matcher.set_seq2(word)  # difflib's side too: the query is the indexed sequence b
        lcs = _LcsBound(word)
        for row, bound in zip(rows.tolist(), bounds.tolist()):
            # Candidates come best bound first: once the bound is below the n-th best ratio found,
            # no later name can enter the top n (ratio <= bound).
            floor = max(cutoff, best[0][0]) if len(best) == n else cutoff
            if bound < floor - 1e-9:
                break
            name = self.names[row]
            total = len(name) + len(word)
            # ratio counts matching blocks, which form a common subsequence: 2 * LCS / total bounds it
            if total and 2.0 * lcs.length(name) / total < floor - 1e-9:
                continue
            matcher.set_seq1(name)
            # ratio >= cutoff implies difflib's real_quick_ratio and quick_ratio checks (both bound it)
            ratio = matcher.ratio()
            if ratio >= cutoff:
                if len(best) < n:
                    heapq.heappush(best, (ratio, name))
                else:
                    heapq.heappushpop(best, (ratio, name))
        return [name for _, name in sorted(best, reverse=True)]

    @classmethod
    def for_names(cls, collection: Any) -> "FuzzyIndex":
        """The index of a long-lived, read-only collection of names (a list, or a dict's keys),
        built on first use and reused (see `_cached_index`)."""
        return _cached_index(cls, collection)


class PrefixIndex:
    """Names starting with a prefix, in sorted order, by binary search over the sorted names:
    equal to `sorted({n for n in names if n.startswith(prefix)})[:limit]` without the scan.

    Args:
        names: The names (any iterable of str; duplicates are dropped, as the set above drops them).
    """

    def __init__(self, names: Iterable[str]) -> None:
        self.names: list[str] = sorted(set(names))

    def __len__(self) -> int:
        return len(self.names)

    def starting_with(self, prefix: str, limit: int) -> list[str]:
        out: list[str] = []
        at = bisect.bisect_left(self.names, prefix)
        while at < len(self.names) and len(out) < limit and self.names[at].startswith(prefix):
            out.append(self.names[at])
            at += 1
        return out

    @classmethod
    def for_names(cls, collection: Any) -> "PrefixIndex":
        """The index of a long-lived, read-only collection of names (see `_cached_index`)."""
        return _cached_index(cls, collection)


_CACHE: "OrderedDict[tuple[type, int], tuple[Any, int, Any]]" = OrderedDict()
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 32


def _cached_index(kind: type, collection: Any) -> Any:
    """`kind(collection)`, built once per collection object and reused while the same object is
    passed with the same length (a database's name table lives for the process; its episodes
    share it). The cache holds a reference to the collection, so its id cannot be reused by
    another object while cached; a length change (names added or removed) rebuilds the index."""
    key = (kind, id(collection))
    with _CACHE_LOCK:
        hit = _CACHE.get(key)
        if hit is not None and hit[0] is collection and hit[1] == len(collection):
            _CACHE.move_to_end(key)
            return hit[2]
    index = kind(collection)
    with _CACHE_LOCK:
        _CACHE[key] = (collection, len(collection), index)
        _CACHE.move_to_end(key)
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return index


class _LcsBound:
    """Length of the longest common subsequence of a fixed word and any string, bit-parallel
    (Hyyro 2004): one pass over the other string, a few integer operations per character."""

    def __init__(self, word: str) -> None:
        self.width = len(word)
        self.mask = (1 << self.width) - 1
        self.positions: dict[str, int] = {}
        for i, ch in enumerate(word):
            self.positions[ch] = self.positions.get(ch, 0) | (1 << i)

    def length(self, other: str) -> int:
        row, positions, mask = self.mask, self.positions, self.mask
        for ch in other:
            matches = row & positions.get(ch, 0)
            row = ((row + matches) | (row - matches)) & mask
        return self.width - row.bit_count()


def close_matches(word: str, names: Any, n: int = 3, cutoff: float = 0.6) -> list[str]:
    """`difflib.get_close_matches(word, names, n, cutoff)` through the cached index of `names`
    (a long-lived, read-only list or dict of names)."""
    return FuzzyIndex.for_names(names).close_matches(word, n=n, cutoff=cutoff)


def names_starting_with(prefix: str, names: Any, limit: int) -> list[str]:
    """`sorted({n for n in names if n.startswith(prefix)})[:limit]` through the cached sorted
    index of `names` (a long-lived, read-only list or dict of names)."""
    return PrefixIndex.for_names(names).starting_with(prefix, limit)
