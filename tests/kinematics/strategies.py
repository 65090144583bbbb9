"""Hypothesis strategies for points inside the build volume."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

SIDE = 170.0


def _triangle_point(a: float, b: float, side: float = SIDE) -> tuple[float, float]:
    """Map (a, b) in [0,1]^2 to a point of the build triangle (vertex on +y)."""
    if a + b > 1.0:
        a, b = 1.0 - a, 1.0 - b
    r = side / np.sqrt(3.0)
    v = np.array([[0.0, r], [-side / 2, -r / 2], [side / 2, -r / 2]])
    p = v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0])
    return float(p[0]), float(p[1])


unit = st.floats(0.0, 1.0, allow_nan=False)


@st.composite
def build_points(draw, z_min: float = 110.0, z_max: float = 330.0, shrink: float = 0.98):
    x, y = _triangle_point(draw(unit), draw(unit), SIDE * shrink)
    z = draw(st.floats(z_min, z_max, allow_nan=False))
    return np.array([x, y, z])


@st.composite
def point_clouds(draw, max_size: int = 64):
    n = draw(st.integers(1, max_size))
    return np.stack([draw(build_points()) for _ in range(n)])
