"""A segment's ramp: the one time profile every axis of a segment follows, and the step
timing on it.

Every axis follows the normalised profile ``p(tau) = 2 r tau + (1 - 2 r) tau**2`` with
``tau = t / D`` (``D`` the segment's duration), so the joint-space path is the straight
line between the endpoints and the speed changes linearly from ``2 r n / D`` (start) to
``(2 - 2 r) n / D`` (end), ``n`` the axis's steps. A ramp code says ``r``: ``r = code /
255`` for codes 0..255; ``RAMP_CONSTANT`` (no ramp byte on the wire) is ``r = 1/2``.
Code 0 starts from rest; code 255 ends at rest.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

RAMP_CONSTANT = -1
RAMP_FROM_REST = 0
RAMP_TO_REST = 255


def ramp_share(codes: np.ndarray | int) -> np.ndarray:
    """``r`` for each ramp code (0.5 for RAMP_CONSTANT)."""
    c = np.asarray(codes, dtype=np.float64)
    return np.where(c < 0, 0.5, c / 255.0)


def ramp_codes_from_speeds(v_start: np.ndarray, v_end: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """Ramp codes for segments whose speed goes linearly from ``v_start`` to ``v_end`` (>= 0)."""
    v0 = np.asarray(v_start, dtype=np.float64)
    v1 = np.asarray(v_end, dtype=np.float64)
    total = v0 + v1
    with np.errstate(invalid="ignore", divide="ignore"):
        code = np.rint(255.0 * v0 / total)
    constant = (total <= 0) | (np.abs(v0 - v1) <= tol * total)
    return np.where(constant, RAMP_CONSTANT, code).astype(np.int16)


def profile(tau: np.ndarray | float, codes: np.ndarray | int) -> np.ndarray:
    """Normalised position ``p(tau)`` in [0, 1]."""
    r = ramp_share(codes)
    t = np.asarray(tau, dtype=np.float64)
    return 2.0 * r * t + (1.0 - 2.0 * r) * t * t


def ends_at_rest(deltas: ArrayLike, codes: np.ndarray | int) -> np.ndarray:
    """For each segment (a row of ``deltas``, one step delta an axis): whether it ends at
    rest, ramping down to it or not moving at all."""
    moving = np.atleast_2d(np.asarray(deltas)).any(axis=1)
    return np.asarray((np.asarray(codes).reshape(-1) == RAMP_TO_REST) | ~moving, dtype=bool)


def step_times(steps: int, ticks: int, code: int) -> np.ndarray:
    """Tick offsets of the |steps| step pulses of one axis within a segment.

    Step j (1-based) is issued when ``|n| p(tau)`` crosses ``j - 1/2``, so pulses are
    spread evenly along the profile and exactly |n| pulses are issued. The form
    ``x / (r + sqrt(r^2 + (1 - 2r) x))`` is the stable root of ``p(tau) = x``.
    """
    n = abs(int(steps))
    if n == 0:
        return np.zeros(0)
    r = float(ramp_share(code))
    x = (np.arange(1, n + 1) - 0.5) / n
    tau = x / (r + np.sqrt(r * r + (1.0 - 2.0 * r) * x))
    return tau * ticks


def steps_done(deltas: ArrayLike, code: int, tau: float) -> np.ndarray:
    """Signed steps already issued at normalised time ``tau`` (consistent with step_times)."""
    d = np.asarray(deltas, dtype=np.int64)
    p = float(profile(min(max(tau, 0.0), 1.0), code))
    return np.sign(d) * np.floor(np.abs(d) * p + 0.5).astype(np.int64)
