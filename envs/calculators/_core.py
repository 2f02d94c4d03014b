"""Shared result type, error type and cheap input validators for every calculator.

Why plain checks instead of a pydantic model per call: the calculators are called in the inner
loop of RL rollouts and reward functions, so one call must cost a few microseconds. Each
validator below is a couple of type checks and one chained comparison; pydantic is used only
for the :class:`ScoreResult` type, which is built with ``model_construct`` once every input has
been checked here (the fields are then correct by construction; see :func:`make_result`).

Conventions (see README.md in this package):

* measurements are ``float`` (ints accepted), item answers and counts are ``int``, yes/no
  criteria are ``bool`` (0/1 integers are *not* accepted: a yes/no criterion that receives a
  number is more likely a mis-mapped argument than a truthy answer), categorical inputs are
  ``Literal`` strings;
* ``bool`` is rejected where a number is expected (``True`` is an ``int`` in Python);
* NaN and infinities are rejected (they fail every range comparison);
* every error is a :class:`CalculatorInputError` whose message names the function, the
  argument and its valid range, e.g.
  ``calculate_gcs: argument 'eye' must be an integer in 1..4, got 5``.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

from pydantic import BaseModel, ConfigDict

__all__ = [
    "CalculatorInputError",
    "ScoreResult",
    "make_result",
    "check_number",
    "check_optional_number",
    "check_int",
    "check_bool",
    "check_choice",
    "check_responses",
    "fmt",
]


class CalculatorInputError(ValueError):
    """An input is missing, of the wrong type, out of its valid range or inconsistent.

    Attributes:
        function: The calculator's name, e.g. ``"calculate_gcs"``.
        argument: The offending argument's name.
        expected: Human-readable description of what is valid (type and range).
        value: The value that was received.
    """

    def __init__(self, function: str, argument: str, expected: str, value: Any) -> None:
        self.function = function
        self.argument = argument
        self.expected = expected
        self.value = value
        super().__init__(f"{function}: argument '{argument}' must be {expected}, got {value!r}")


class ScoreResult(BaseModel):
    """The result of one clinical instrument.

    Attributes:
        instrument: The instrument's usual name, e.g. "Glasgow Coma Scale".
        score: The instrument's number: points, level or measured value (``float`` for
            equations, ``int`` for point scores and levels).
        unit: Unit of ``score`` ("points", "mL/min/1.73 m2", "ms", "level", ...).
        category: The band or class, e.g. "high risk", "TR4", "Class B", "ESI 2".
        interpretation: One clinical sentence.
        components: Points (or derived values) per criterion, keyed by criterion name.
        reference: The published source the computation follows.
        flags: Safety-relevant findings that need action regardless of the band (e.g. a
            positive PHQ-9 item 9).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    instrument: str
    score: int | float
    unit: str
    category: str
    interpretation: str
    components: dict[str, int | float | str | bool | None]
    reference: str
    flags: tuple[str, ...] = ()


_new = object.__new__
_set = object.__setattr__
_ALL_FIELDS = frozenset(ScoreResult.model_fields)


def make_result(
    instrument: str,
    score: int | float,
    unit: str,
    category: str,
    interpretation: str,
    components: dict[str, Any],
    reference: str,
    flags: tuple[str, ...] = (),
) -> ScoreResult:
    """Build a ScoreResult without re-validation (the caller has validated every input).

    This does what ``ScoreResult.model_construct`` does (set the field dict and pydantic's
    bookkeeping slots on an uninitialised instance) without its generic per-field default and
    alias handling, which costs about 10 us, five times the rest of a typical calculator. The
    test suite checks that every calculator's result round-trips through full validation.
    """
    obj = _new(ScoreResult)
    _set(
        obj,
        "__dict__",
        {
            "instrument": instrument,
            "score": score,
            "unit": unit,
            "category": category,
            "interpretation": interpretation,
            "components": components,
            "reference": reference,
            "flags": flags,
        },
    )
    _set(obj, "__pydantic_fields_set__", _ALL_FIELDS)
    _set(obj, "__pydantic_extra__", None)
    _set(obj, "__pydantic_private__", None)
    return obj


def fmt(value: float, digits: int = 1) -> str:
    """Format a number for an interpretation sentence (no trailing '.0' for integers)."""
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.{digits}f}"


def _range(lo: float, hi: float, unit: str) -> str:
    text = f"{lo:g}..{hi:g}"
    return f"{text} {unit}" if unit else text


def check_number(fn: str, name: str, value: Any, lo: float, hi: float, unit: str = "") -> float:
    """Return ``value`` if it is a finite real number (not bool) in ``lo..hi``, else raise."""
    tp = type(value)
    if tp is float or tp is int:
        if lo <= value <= hi:  # NaN fails this comparison
            return value
    elif tp is not bool and isinstance(value, Real):  # numpy scalars, Fraction, Decimal-free
        as_float = float(value)
        if lo <= as_float <= hi:
            return as_float
    raise CalculatorInputError(fn, name, f"a number in {_range(lo, hi, unit)}", value)


def check_optional_number(
    fn: str, name: str, value: Any, lo: float, hi: float, unit: str = ""
) -> float | None:
    """Like :func:`check_number` but ``None`` (not measured) passes through."""
    if value is None:
        return None
    return check_number(fn, name, value, lo, hi, unit + " or None" if unit else "or None")


def check_int(fn: str, name: str, value: Any, lo: int, hi: int, unit: str = "") -> int:
    """Return ``value`` if it is an integer (not bool) in ``lo..hi``, else raise."""
    tp = type(value)
    if tp is int:
        if lo <= value <= hi:
            return value
    elif tp is not bool and isinstance(value, Integral):
        as_int = int(value)
        if lo <= as_int <= hi:
            return as_int
    raise CalculatorInputError(fn, name, f"an integer in {_range(lo, hi, unit)}", value)


def check_bool(fn: str, name: str, value: Any) -> bool:
    """Return ``value`` if it is ``True`` or ``False``, else raise."""
    if value is True or value is False:
        return value
    raise CalculatorInputError(fn, name, "a boolean (true or false)", value)


def check_choice(fn: str, name: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of the allowed strings, else raise."""
    if type(value) is str and value in choices:
        return value
    raise CalculatorInputError(fn, name, "one of " + ", ".join(repr(c) for c in choices), value)


def check_responses(fn: str, name: str, value: Any, count: int, lo: int, hi: int) -> list[int]:
    """Return a questionnaire's answers if they are exactly ``count`` integers in ``lo..hi``."""
    expected = f"a list of {count} integers, each in {lo}..{hi}"
    if not isinstance(value, (list, tuple)) or len(value) != count:
        raise CalculatorInputError(fn, name, expected, value)
    out: list[int] = []
    for item in value:
        tp = type(item)
        if tp is int and lo <= item <= hi:
            out.append(item)
        elif tp is not bool and tp is not int and isinstance(item, Integral) and lo <= int(item) <= hi:
            out.append(int(item))
        else:
            raise CalculatorInputError(fn, name, expected, value)
    return out
