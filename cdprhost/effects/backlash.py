"""`backlash`: half lash beta_k, s_actual = s_cmd - beta_k d_k.

``d_k`` is the sign of module k's last motion. Compensation adds beta_k d_k, so
the commanded position leads the wanted one in the direction of travel.
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.effects.base import Effect, MotionContext, stderr_fields, vector3

Lash = Annotated[float, Field(ge=-5.0, le=5.0, allow_inf_nan=False)]


class BacklashParams(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    beta: tuple[Lash, Lash, Lash] = Field(description="half lash per module (mm)")
    beta_stderr: tuple[float, float, float] | None = None


class Backlash(Effect):
    name = "backlash"
    stage = "slider"
    params_model = BacklashParams
    vector_names = ("beta_1", "beta_2", "beta_3")
    description = (
        "each module lags its commanded position by beta_k against its direction of travel"
    )

    def to_vector(self, params: BaseModel) -> np.ndarray:
        assert isinstance(params, BacklashParams)
        return vector3(params.beta)

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        return {
            "beta": [float(v) for v in vector],
            **stderr_fields(self.vector_names, stderr, "beta"),
        }

    @staticmethod
    def _dirs(s: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return (
            np.zeros_like(s) if ctx.directions is None else np.asarray(ctx.directions, dtype=float)
        )

    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s - vector * self._dirs(s, ctx)

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s + vector * self._dirs(s, ctx)


def path_directions(s: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
    """Sign of each module's last motion at every point of a path (N, 3), vectorised.

    A point where a module does not move keeps the previous sign; before the first
    motion the sign is ``initial`` (default: the sign of the first motion).
    """
    s = np.asarray(s, dtype=float)
    n = s.shape[0]
    d = np.zeros_like(s)
    if n > 1:
        d[1:] = np.sign(np.diff(s, axis=0))
    # forward-fill zeros with the last nonzero sign, per column
    idx = np.where(d != 0, np.arange(n)[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    filled = np.take_along_axis(d, idx, axis=0)
    first_nonzero = np.where((d != 0).any(axis=0), d[np.argmax(d != 0, axis=0), np.arange(3)], 1.0)
    start = first_nonzero if initial is None else np.asarray(initial, dtype=float)
    filled = np.where(filled == 0, start[None, :], filled)
    return filled
