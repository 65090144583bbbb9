"""Truth-only effects outside the catalogue, for hidden-effect tests.

They implement the :class:`cdprhost.effects.base.Effect` interface so the
simulator's true machine can carry them, but they are not registered: the
diagnosis workflow cannot name them and must answer ``unexplained``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import BaseModel

from cdprhost.effects.base import Effect, MotionContext


class _NoParams(BaseModel):
    pass


class PeriodicLeadError(Effect):
    """Lead-screw periodic error: s_act = s + a_k sin(2 pi s / P + phi_k).

    Vector: (a_1, a_2, a_3, P, phi_1, phi_2, phi_3); mm, mm, rad.
    """

    name = "periodic_lead_error"
    stage = "slider"
    params_model = _NoParams
    vector_names = ("a_1", "a_2", "a_3", "period", "phi_1", "phi_2", "phi_3")
    description = "slider position error repeating every screw turn"

    def to_vector(self, params: BaseModel) -> np.ndarray:
        raise NotImplementedError

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        return {"vector": [float(v) for v in vector]}

    def null_vector(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.0, 8.0, 0.0, 0.0, 0.0])

    def _error(self, s: np.ndarray, v: np.ndarray) -> np.ndarray:
        return v[:3] * np.sin(2.0 * np.pi * s / v[3] + v[4:7])

    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s + self._error(s, vector)

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        out = s
        for _ in range(8):  # fixed point: the error is small and slowly varying
            out = s - self._error(out, vector)
        return out


class SliderOffset(Effect):
    """A constant slider offset per module: exactly what L_k0 does, so absorbed."""

    name = "slider_offset"
    stage = "slider"
    params_model = _NoParams
    vector_names = ("c_1", "c_2", "c_3")
    description = "constant offset of each slider"

    def to_vector(self, params: BaseModel) -> np.ndarray:
        raise NotImplementedError

    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        return {"c": [float(v) for v in vector]}

    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s + vector

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        return s - vector


def periodic_vector(
    rng: np.random.Generator,
    amplitude_mm: tuple[float, float] = (0.12, 0.25),
    period_mm: float = 8.0,
) -> np.ndarray:
    """A periodic lead error of realistic size: 0.12-0.25 mm amplitude, one lead (8 mm) period."""
    return np.concatenate(
        [rng.uniform(*amplitude_mm, 3), [period_mm], rng.uniform(0, 2 * np.pi, 3)]
    )
