"""Cornering speed between consecutive moves (Klipper's junction deviation model).

The corner is approximated by a circle tangent to both moves that deviates
``junction_deviation`` from the corner point; the junction speed is the speed
whose centripetal acceleration on that circle equals the move's acceleration:

    v^2 = a * jd * sin(theta/2) / (1 - sin(theta/2))

with theta the angle between the reversed incoming direction and the outgoing
one (pi: straight on, no limit; 0: full reversal, stop). As in Klipper the circle
may not reach past either move's midpoint: v^2 <= a d tan(theta/2) / 2. Moves
that do not move the effector (extrude only) meet their neighbours at rest.
"""

from __future__ import annotations

import numpy as np


def junction_v2(
    unit: np.ndarray,
    kinematic: np.ndarray,
    accel: np.ndarray,
    length: np.ndarray,
    junction_deviation: float | np.ndarray,
) -> np.ndarray:
    """Squared speed limit at the n-1 inner junctions of n consecutive moves.

    ``junction_deviation``: one value, or one per junction (n-1,).
    """
    if unit.shape[0] < 2:
        return np.zeros(0)
    u0, u1 = unit[:-1], unit[1:]
    cos_theta = -np.einsum("ij,ij->i", u0, u1)  # Klipper's sign: -1 straight on, +1 reversal
    sin_half = np.sqrt(np.maximum(0.5 * (1.0 - cos_theta), 0.0))
    cos_half = np.sqrt(np.maximum(0.5 * (1.0 + cos_theta), 0.0))
    one_minus = 1.0 - sin_half
    v2 = np.full(cos_theta.shape, np.inf)
    corner = (one_minus > 0) & (cos_half > 0)
    r_jd = sin_half[corner] / one_minus[corner]
    a0, a1 = accel[:-1][corner], accel[1:][corner]
    quarter_tan = 0.25 * sin_half[corner] / cos_half[corner]
    if np.ndim(junction_deviation):
        junction_deviation = np.asarray(junction_deviation)[corner]
    d0, d1 = length[:-1][corner], length[1:][corner]
    v2[corner] = np.minimum.reduce(
        [
            r_jd * junction_deviation * a0,
            r_jd * junction_deviation * a1,
            2.0 * a0 * d0 * quarter_tan,
            2.0 * a1 * d1 * quarter_tan,
        ]
    )
    both = kinematic[:-1] & kinematic[1:]
    v2[~both] = 0.0
    return v2
