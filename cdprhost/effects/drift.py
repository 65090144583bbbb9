"""`drift`: slow creep of each module, s_actual = s_cmd + rho_k t.

Not compensated while printing (t is unknown there); diagnosis reports it and
advises re-zeroing.
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.effects.base import Effect, MotionContext, stderr_fields, vector3

Rate = Annotated[float, Field(ge=-1.0, le=1.0, allow_inf_nan=False)]


class DriftParams(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    rho: tuple[Rate, Rate, Rate] = Field(description="creep rate per module (mm/s)")
    rho_stderr: tuple[float, float, float] | None = None


class Drift(Effect):
    name = "drift"
    stage = "slider"
    params_model = DriftParams
    vector_names = ("rho_1", "rho_2", "rho_3")
    description = "each module creeps at rho_k mm/s over a session"

    def to_vector(self, params: BaseModel) -> np.ndarray:
        assert isinstance(params, DriftParams)
        return vector3(params.rho)

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        return {
            "rho": [float(v) for v in vector],
            **stderr_fields(self.vector_names, stderr, "rho"),
        }

    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        if ctx.t_s is None:
            return s
        return s + vector * np.asarray(ctx.t_s, dtype=float)[:, None]

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        if ctx.t_s is None:
            return s
        return s - vector * np.asarray(ctx.t_s, dtype=float)[:, None]
