"""Request/response schemas of the HTTP API (pydantic).  No solver imports here."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt

Number = StrictFloat | StrictInt


class NurbsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    type: Literal["nurbs"] = "nurbs"
    degree: StrictInt = Field(ge=1, le=12)
    knots: list[Number]
    control_points: list[Annotated[list[Number], Field(min_length=2, max_length=3)]]
    weights: list[Number] | None = None


class ToolpathIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    segments: list[NurbsIn] = Field(min_length=1, max_length=10_000)
    corner_tolerance_deg: Number = 0.5


class OptionsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    method: Literal["lp"] = "lp"
    sample_period: Number = Field(default=0.001, gt=0, le=0.1)
    knot_spacing: Number | None = Field(default=None, gt=0)
    checkpoints_per_interval: StrictInt = Field(default=5, ge=1, le=64)
    jerk: bool = True
    solver: Literal["highs", "clarabel"] = "highs"
    feed_max: Number | None = Field(default=None, gt=0)


EXAMPLE = {
    "toolpath": {
        "segments": [
            {
                "type": "nurbs",
                "degree": 2,
                "knots": [0, 0, 0, 1, 1, 1],
                "control_points": [[0, 0, 0], [40, 0, 0], [40, 40, 0]],
                "weights": [1, 0.7071067811865476, 1],
            }
        ]
    },
    "machine": "router",
    "options": {"method": "lp", "sample_period": 0.001},
}


class ScheduleRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [EXAMPLE]})
    toolpath: ToolpathIn
    machine: Literal["router"] = "router"
    options: OptionsIn = OptionsIn()


class ScheduleResponse(BaseModel):
    summary: dict[str, Any]
    diagnostics: dict[str, Any]
    samples: dict[str, list[float]]
