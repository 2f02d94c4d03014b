"""The reward's data types: weights (input), violations and the breakdown (output).

All three are pydantic models because they cross boundaries: weights come from configs and the
environment's constructor, the breakdown is stored with every trajectory
(`Trajectory.reward_details`) and logged by training.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, ValidationInfo, create_model, field_validator,
                      model_validator)

from envs.rewards.dimensions import ALWAYS_REPORTED, DIMENSIONS
from envs.rewards.violation import Principle, Violation

#: The reward dimensions' names in report order (the registry: `envs.rewards.dimensions`).
DIMENSION_NAMES: tuple[str, ...] = tuple(d.name for d in DIMENSIONS)


def _finite_non_negative(value: float, info: ValidationInfo) -> float:
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{info.field_name} must be a finite number >= 0, got {value!r}")
    return float(value)


Weight = Annotated[float, AfterValidator(_finite_non_negative)]


class _Weights(BaseModel):
    """Weights of the 5D reward (paper section 3) and the safety penalties (paper Table 6).

    The total is a *normalised* weighted sum: `sum(w_j * R_j) / sum(w_j)` over the dimensions
    that apply to the task (see `docs/rewards.md`), so it lies in [0, 1] before penalties
    whatever the weights' scale. One weight field per registered dimension
    (`envs.rewards.dimensions`), named as the dimension, defaulting to its `default_weight`.
    Build from a dict with `RewardWeights.model_validate(d)` or pass the dict to `score_episode`;
    unknown keys, negative or non-finite values, and weights that are all zero are rejected with a
    message naming the field.

    Example:
        >>> RewardWeights(accuracy=0.5).accuracy
        0.5
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: The total is capped at this value when any severity-5 (critical) violation occurs.
    critical_cap: Weight = 0.1
    #: Subtracted from the total once per distinct violation of severity 4, 3, 2, 1.
    severity_penalties: dict[int, float] = Field(
        default_factory=lambda: {4: 0.30, 3: 0.15, 2: 0.05, 1: 0.01}
    )
    #: `RewardBreakdown.is_correct` needs `accuracy >= correct_threshold`.
    correct_threshold: Weight = 0.5
    #: The total never goes below this after penalties (0 keeps it in [0, 1]).
    floor: Weight = 0.0

    @field_validator("severity_penalties")
    @classmethod
    def _penalties(cls, value: dict[int, float]) -> dict[int, float]:
        out: dict[int, float] = {}
        for severity, penalty in value.items():
            if severity not in (1, 2, 3, 4):
                raise ValueError(f"severity_penalties keys must be 1, 2, 3 or 4 (5 caps the total), got {severity!r}")
            if not math.isfinite(penalty) or penalty < 0:
                raise ValueError(f"severity_penalties[{severity}] must be a finite number >= 0, got {penalty!r}")
            out[int(severity)] = float(penalty)
        return {s: out.get(s, 0.0) for s in (1, 2, 3, 4)}

    @model_validator(mode="after")
    def _some_weight(self) -> "_Weights":
        if sum(self.weight(name) for name in ALWAYS_REPORTED) <= 0:
            raise ValueError(f"at least one of {', '.join(ALWAYS_REPORTED)} must be > 0")
        if self.critical_cap > 1 or self.correct_threshold > 1 or self.floor > 1:
            raise ValueError("critical_cap, correct_threshold and floor must be <= 1")
        return self

    def weight(self, dimension: str) -> float:
        if dimension not in DIMENSION_NAMES:
            raise KeyError(f"no reward dimension {dimension!r}; dimensions: {', '.join(DIMENSION_NAMES)}")
        return float(getattr(self, dimension))

    @classmethod
    def coerce(cls, weights: "RewardWeights | dict[str, Any] | None") -> "RewardWeights":
        """Accept a RewardWeights, a dict of its fields, or None (the paper's defaults)."""
        if weights is None:
            return DEFAULT_WEIGHTS
        if isinstance(weights, RewardWeights):
            return weights
        if isinstance(weights, dict):
            return RewardWeights.model_validate(weights)
        raise TypeError(f"weights must be RewardWeights, a dict or None, got {type(weights).__name__}")


RewardWeights = create_model(
    "RewardWeights", __base__=_Weights, __module__=__name__, __doc__=_Weights.__doc__,
    **{d.name: (Weight, Field(default=d.default_weight, description=d.summary)) for d in DIMENSIONS},
)

DEFAULT_WEIGHTS = RewardWeights()


class _Breakdown(BaseModel):
    """What `score_episode` returns: every dimension, the penalties and the total.

    One score field per registered dimension (`envs.rewards.dimensions`), named as the dimension: a
    float, or `float | None` (None: did not apply) for a dimension not always reported.
    `total` = clip(normalised weighted sum - penalties, floor, 1), then min(., critical_cap) when
    a severity-5 violation occurred. `weights` holds the effective weights (normalised to sum to
    1 over the dimensions that applied; 0 for a dimension that did not apply).
    """

    model_config = ConfigDict(extra="forbid")
    total: float
    base_total: float                       # the normalised weighted sum before penalties
    penalty: float = 0.0                    # sum of severity 1-4 penalties subtracted
    capped: bool = False                    # a severity-5 violation capped the total
    is_correct: bool = False                # accuracy >= threshold and no critical violation
    violations: list[Violation] = Field(default_factory=list)
    grader_errors: list[str] = Field(default_factory=list)
    weights: dict[str, float] = Field(default_factory=dict)
    details: dict[str, Any] = Field(default_factory=dict)

    def components(self) -> dict[str, float]:
        """Flat name -> float map for `info["reward_components"]` and training logs.

        Always has the always-reported dimensions (accuracy, process, safety, format, coherence),
        `safety_penalty` and `total`; another dimension (assertion) only when it applied.
        """
        out = {name: float(score) for name in DIMENSION_NAMES if (score := getattr(self, name)) is not None}
        out["safety_penalty"] = float(self.penalty)
        out["total"] = float(self.total)
        return out

    @property
    def max_severity(self) -> int:
        return max((v.severity for v in self.violations), default=0)


RewardBreakdown = create_model(
    "RewardBreakdown", __base__=_Breakdown, __module__=__name__, __doc__=_Breakdown.__doc__,
    **{d.name: ((float, ...) if d.always_reported else (float | None, None)) for d in DIMENSIONS},
)
