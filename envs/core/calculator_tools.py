"""Expose `envs.calculators` functions as toolkit methods under their own names: the one way a
domain offers a calculator as a tool (`calculate_bmi = calculator_method("calculate_bmi")` in its
toolkit class body).

The calculator's signature and Google-style docstring become the tool schema unchanged; the tool
returns the calculator's `ScoreResult` as a dict. Input errors surface as the calculator's own
`CalculatorInputError` (a ValueError naming the argument and its valid range).
"""

from __future__ import annotations

import inspect
import typing
from typing import Any, Callable

from envs.calculators import CALCULATORS
from envs.core.tools import ToolType, is_tool


def calculator_method(name: str) -> Callable:
    """A READ tool method (taking `self`) that runs the calculator `name` from envs.calculators."""
    fn = CALCULATORS[name]
    hints = typing.get_type_hints(fn)
    signature = inspect.signature(fn)

    def method(self: Any, **kwargs: Any) -> dict:
        return fn(**kwargs).model_dump(mode="json")

    params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    params += [p.replace(annotation=hints.get(p.name, p.annotation)) for p in signature.parameters.values()]
    method.__signature__ = signature.replace(parameters=params, return_annotation=dict)  # type: ignore[attr-defined]
    method.__annotations__ = {k: v for k, v in hints.items() if k != "return"} | {"return": dict}
    method.__doc__ = fn.__doc__
    method.__name__ = name
    method.__qualname__ = name
    return is_tool(ToolType.READ)(method)
