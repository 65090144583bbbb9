"""`drive_scale`: a lead screw whose pitch is off, s_actual = (1 + eps_k) s_cmd."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.effects.base import Effect, MotionContext, stderr_fields, vector3

Eps = Annotated[float, Field(gt=-0.5, lt=0.5, allow_inf_nan=False)]


class DriveScaleParams(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    eps: tuple[Eps, Eps, Eps] = Field(description="relative scale error per module (-)")
    eps_stderr: tuple[float, float, float] | None = None


class DriveScale(Effect):
    name = "drive_scale"
    stage = "slider"
    params_model = DriveScaleParams
    vector_names = ("eps_1", "eps_2", "eps_3")
    description = "each module moves (1 + eps_k) times the commanded distance"

    def to_vector(self, params: BaseModel) -> np.ndarray:
        assert isinstance(params, DriveScaleParams)
        return vector3(params.eps)

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        return {
            "eps": [float(v) for v in vector],
            **stderr_fields(self.vector_names, stderr, "eps"),
        }

    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s * (1.0 + vector)

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s / (1.0 + vector)
