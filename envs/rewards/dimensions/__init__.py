"""The reward's dimensions, one module each.

A module in this package that defines `DIMENSION` (an `envs.rewards.dimensions.base.Dimension`)
is a reward dimension: `score_episode` grades it, `RewardWeights` has its weight, `RewardBreakdown`
its score, `components()` and the verl keys its name. Nothing else lists the dimensions.

    DIMENSIONS       the dimensions in report order (by `position`)
    GRADING_ORDER    the same, ordered so every dimension comes after the ones it reads (`after`)
"""

from __future__ import annotations

import importlib
import pkgutil

from envs.rewards.dimensions.base import Dimension, Graded, Grading


def _discover() -> tuple[Dimension, ...]:
    """Every `DIMENSION` defined by a module of this package, in report order."""
    declared: list[tuple[str, Dimension]] = []
    for module_info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        if hasattr(module, "DIMENSION"):
            declared.append((module.__name__, module.DIMENSION))
    return registry(declared)


def registry(declared: list[tuple[str, Dimension]]) -> tuple[Dimension, ...]:
    """(module name, declared dimension) pairs checked and put in report order: each a `Dimension`
    with an identifier for a name, declared once, reading only declared dimensions."""
    found: dict[str, Dimension] = {}
    for source, dimension in declared:
        if not isinstance(dimension, Dimension):
            raise TypeError(f"{source}.DIMENSION must be a Dimension, got {type(dimension).__name__}")
        if not dimension.name.isidentifier():
            raise ValueError(f"{source}: dimension name {dimension.name!r} is not a Python identifier")
        if dimension.name in found:
            raise ValueError(f"{source}: dimension {dimension.name!r} is declared twice")
        found[dimension.name] = dimension
    ordered = sorted(found.values(), key=lambda d: (d.position, d.name))
    for dimension in ordered:
        unknown = [name for name in dimension.after if name not in found]
        if unknown:
            raise ValueError(f"dimension {dimension.name!r} is graded after unknown dimension(s) {unknown}; "
                             f"known: {sorted(found)}")
    return tuple(ordered)


def grading_order(dimensions: tuple[Dimension, ...]) -> tuple[Dimension, ...]:
    """Report order, each dimension preceded by those it reads (depth first); refuses a cycle."""
    by_name = {d.name: d for d in dimensions}
    order: list[Dimension] = []
    state: dict[str, str] = {}

    def visit(dimension: Dimension, path: tuple[str, ...]) -> None:
        if state.get(dimension.name) == "done":
            return
        if state.get(dimension.name) == "visiting":
            raise ValueError(f"reward dimensions read each other in a cycle: {' -> '.join(path + (dimension.name,))}")
        state[dimension.name] = "visiting"
        for name in dimension.after:
            visit(by_name[name], path + (dimension.name,))
        state[dimension.name] = "done"
        order.append(dimension)

    for dimension in dimensions:
        visit(dimension, ())
    return tuple(order)


DIMENSIONS: tuple[Dimension, ...] = _discover()
GRADING_ORDER: tuple[Dimension, ...] = grading_order(DIMENSIONS)
#: Names of the dimensions in every breakdown and `components()` (verl needs the same keys per sample).
ALWAYS_REPORTED: tuple[str, ...] = tuple(d.name for d in DIMENSIONS if d.always_reported)

__all__ = ["Dimension", "Graded", "Grading", "DIMENSIONS", "GRADING_ORDER", "ALWAYS_REPORTED"]
