"""The project's strict pydantic bases: a typo in a config key or a record field is an error that
names it, never a silently ignored value."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class StrictModel(BaseModel):
    """Unknown fields are rejected (configs, messages between processes)."""

    model_config = ConfigDict(extra="forbid")


class StrictRecord(StrictModel):
    """A strict model whose fields are also validated on assignment (database records that tools
    mutate in place: a write of the wrong type fails at the write, not later)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)
