"""The interface every catalogue effect implements.

The model chain from a commanded slider displacement to the straight-line
distance |B - A_k| the machine realises has two stages:

    s_cmd --slider effects--> s_act;  u = L_k0 + s_act  --cable effects--> |B - A_k|

*Slider* effects (drive scale, backlash, drift) change how far the slider really
moves; *cable* effects (elasticity) change how long the paid-out cable really is.
Prediction runs the chain forward; IK compensation runs it backward. Each effect
exposes its parameters as a flat vector so fitting code can treat it uniformly.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import BaseModel


@dataclass(frozen=True)
class MotionContext:
    """Per-point context some effects need. Arrays are (N,) or (N, 3); None = unknown."""

    t_s: np.ndarray | None = None  # seconds since the session started
    directions: np.ndarray | None = None  # +1/-1/0: sign of each module's last motion


class Effect(ABC):
    name: ClassVar[str]
    stage: ClassVar[Literal["slider", "cable"]]
    params_model: ClassVar[type[BaseModel]]
    vector_names: ClassVar[tuple[str, ...]]
    description: ClassVar[str]

    # --- parameters ------------------------------------------------------
    @abstractmethod
    def to_vector(self, params: BaseModel) -> np.ndarray:
        """Profile parameters -> the flat vector used by the model and by fitting."""

    @abstractmethod
    def to_params(self, vector: np.ndarray, stderr: np.ndarray | None = None) -> dict[str, Any]:
        """Flat vector (and its standard errors) -> a profile ``[effects.<name>]`` table."""

    def null_vector(self) -> np.ndarray:
        """The vector of the ideal machine (effect absent)."""
        return np.zeros(len(self.vector_names))

    def parse(self, table: dict[str, Any]) -> np.ndarray:
        return self.to_vector(self.params_model.model_validate(table))

    # --- model -------------------------------------------------------------
    def apply(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        """Slider stage, forward: commanded -> actual displacement."""
        return s

    def invert(self, s: np.ndarray, vector: np.ndarray, ctx: MotionContext) -> np.ndarray:
        """Slider stage, compensation: wanted actual -> displacement to command."""
        return s

    def stretch(self, u: np.ndarray, tensions: np.ndarray, vector: np.ndarray) -> np.ndarray:
        """Cable stage, forward: unstretched length -> realised length."""
        return u

    def unstretch(self, length: np.ndarray, tensions: np.ndarray, vector: np.ndarray) -> np.ndarray:
        """Cable stage, compensation: wanted realised length -> unstretched length."""
        return length


def vector3(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(3)


def stderr_fields(names: tuple[str, ...], stderr: np.ndarray | None, key: str) -> dict[str, Any]:
    if stderr is None:
        return {}
    if len(names) == 1:
        return {f"{key}_stderr": float(stderr[0])}
    return {f"{key}_stderr": [float(v) for v in stderr]}
