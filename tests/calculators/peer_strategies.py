"""Shared machinery for the peer property tests: input domains, batches, agreement check.

Speed: hypothesis costs about 1 ms per example and tens of microseconds per drawn value, so each
example is a batch of ``BATCH`` inputs and each input is one drawn integer decoded into all its
fields (see :func:`batch`): ``EXAMPLES x BATCH`` = 2,000 inputs per instrument, and shrinking
still reduces a failing batch to its simplest failing input.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

BATCH, EXAMPLES = 40, 50
PEER = settings(
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
)


class Domain:
    """A finite set of input values, indexed 0..size-1 (index 0 is what shrinking goes to)."""

    def __init__(self, size: int, decode):
        self.size, self.decode = size, decode


def ints(lo: int, hi: int) -> Domain:
    return Domain(hi - lo + 1, lambda k: lo + k)


def tenths(lo: float, hi: float) -> Domain:
    """Numbers with one decimal (as charted) in lo..hi."""
    a, z = round(lo * 10), round(hi * 10)
    return Domain(z - a + 1, lambda k: (a + k) / 10)


def hundredths(lo: float, hi: float) -> Domain:
    a, z = round(lo * 100), round(hi * 100)
    return Domain(z - a + 1, lambda k: (a + k) / 100)


def choice(values) -> Domain:
    values = list(values)
    return Domain(len(values), values.__getitem__)


def opt(dom: Domain) -> Domain:
    """None (not measured) or a value of ``dom``."""
    return Domain(dom.size + 1, lambda k: None if k == 0 else dom.decode(k - 1))


def items(n: int, lo: int, hi: int) -> Domain:
    """A questionnaire: ``n`` answers in lo..hi."""
    base = hi - lo + 1
    return Domain(base**n, lambda k: [lo + (k // base**i) % base for i in range(n)])


b = choice([False, True])
sexes = choice(["male", "female"])


def batch(bools: tuple[str, ...] = (), **fields: Domain):
    """A hypothesis strategy for a batch of keyword-argument dicts.

    Each case is one integer drawn by hypothesis and decoded in mixed radix into the fields
    (one draw per case instead of one per field: generation, not the calculators, was the cost).
    Shrinking an integer towards 0 moves every field towards the first value of its domain.
    """
    fields = dict(fields, **{name: b for name in bools})
    names = list(fields)
    sizes = [fields[n].size for n in names]
    total = 1
    for size in sizes:
        total *= size

    def decode(code: int) -> dict:
        out = {}
        for name, size in zip(names, sizes):
            code, k = divmod(code, size)
            out[name] = fields[name].decode(k)
        return out

    return st.lists(st.integers(0, total - 1).map(decode), min_size=BATCH, max_size=BATCH)


def assert_agree(ours, kw: dict, *peer_fns, tol: float = 0.0):
    mine = ours(**kw).score
    for peer in peer_fns:
        theirs = peer(**kw)
        assert theirs == pytest.approx(mine, abs=tol), (
            f"{peer.__name__} gave {theirs}, we gave {mine} for {kw}"
        )
    return mine
