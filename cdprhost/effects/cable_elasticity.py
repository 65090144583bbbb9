"""`cable_elasticity`: cables stretch under tension, stretched = (L_k0 + s_k)(1 + T_k/EA).

The fitting vector holds the compliance 1/EA (1/N), so "no effect" is 0 and the
model is linear in it near the ideal machine.
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.effects.base import Effect, stderr_fields


class CableElasticityParams(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    EA: Annotated[float, Field(gt=0, description="axial stiffness E*A of one equivalent cable (N)")]
    EA_stderr: Annotated[float, Field(ge=0)] | None = None


class CableElasticity(Effect):
    name = "cable_elasticity"
    stage = "cable"
    params_model = CableElasticityParams
    vector_names = ("compliance_per_N",)
    description = "cables stretch in proportion to their tension (shared EA)"

    def to_vector(self, params: BaseModel) -> np.ndarray:
        assert isinstance(params, CableElasticityParams)
        return np.array([1.0 / params.EA])

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        c = float(vector[0])
        out: dict[str, Any] = {"EA": 1.0 / c if c > 0 else float("inf")}
        if stderr is not None and c > 0:
            # delta method: sd(1/c) = sd(c) / c^2
            out.update(stderr_fields(self.vector_names, np.array([stderr[0] / (c * c)]), "EA"))
        return out

    def stretch(self, u: np.ndarray, tensions: np.ndarray, vector: np.ndarray) -> np.ndarray:
        return u * (1.0 + tensions * vector[0])

    def unstretch(self, length: np.ndarray, tensions: np.ndarray, vector: np.ndarray) -> np.ndarray:
        return length / (1.0 + tensions * vector[0])
