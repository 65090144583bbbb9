"""Velocity lookahead as array operations (no per-move Python loop).

Junction j sits before move j (junction 0: the start, junction n: the end). With
``lim`` the squared speed allowed at each junction and ``delta_i = 2 a_i d_i``
what move i can add to (or remove from) v^2, the fastest feasible profile is

    v2[j] = min over m of ( lim[m] + |S[m] - S[j]| ),   S[j] = sum_{k<j} delta_k

split into a backward (deceleration) and a forward (acceleration) pass, each a
cumulative minimum.

Klipper's "minimum cruise ratio" smoothing is reproduced too: a second profile
with a fraction of the acceleration groups moves into accelerate-peak-decelerate
humps, and every move's cruise speed is capped at its hump's smoothed peak. That
keeps short zig-zags from alternating full acceleration and full braking.
"""

from __future__ import annotations

import numpy as np


def limit_passes(lim: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Greatest v^2 at every junction with v2 <= lim and |v2[j+1] - v2[j]| <= delta[j]."""
    s = np.zeros(lim.shape[0])
    np.cumsum(delta, out=s[1:])
    back = np.minimum.accumulate((lim + s)[::-1])[::-1] - s
    fwd = np.minimum.accumulate(back - s) + s
    return np.maximum(np.minimum(fwd, back), 0.0)


def hump_caps(
    lim: np.ndarray, delta_smooth: np.ndarray, cruise_v2: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-move cruise cap from the smoothed profile's hump peaks (Klipper's grouping),
    the smoothed profile itself (v^2 at the junctions) and each move's hump (index of its peak move).

    A move is "decelerating" (D) when its smoothed start is bounded by braking for
    what follows, a "peak" (P) when it can accelerate and either can brake or is
    followed by a D, else "accelerating" (A). Humps are A* P D*; all their moves
    share the P's peak, ``min(cruise, (v_start^2 + v_end^2 + delta)/2)``.
    """
    n = delta_smooth.shape[0]
    sv = limit_passes(lim, delta_smooth)
    if n == 0:
        return cruise_v2.copy(), sv, np.zeros(0, dtype=np.int64)
    start, nxt = sv[:-1], sv[1:]
    reach = nxt + delta_smooth
    tol = 1e-9 * np.maximum(reach, 1.0)
    dec = start >= reach - tol
    next_dec = np.zeros(n, dtype=bool)
    next_dec[:-1] = dec[1:]
    peak = ~dec & ((start + delta_smooth > nxt + tol) | next_dec)
    acc = ~dec & ~peak
    idx = np.arange(n)
    prev_p = np.maximum.accumulate(np.where(peak, idx, -1))
    next_p = np.minimum.accumulate(np.where(peak, idx, n)[::-1])[::-1]
    owner = np.where(acc, next_p, prev_p)
    owner = np.where((owner < 0) | (owner >= n), idx, owner)
    peak_v2 = np.minimum(cruise_v2, 0.5 * (start + reach))
    return np.minimum(cruise_v2, peak_v2[owner]), sv, owner


def plan_profile(
    junction_v2: np.ndarray,
    cruise_v2: np.ndarray,
    delta: np.ndarray,
    v2_start: float,
    v2_end: float,
    *,
    min_cruise_ratio: float = 0.0,
    smooth_v2_start: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Junction speeds^2 (n+1,), cruise speeds^2 (n,), the smoothed profile (n+1,) and
    where humps start ((n,) bool; every move without smoothing) of n moves.

    ``junction_v2`` (n-1,) are the cornering limits between moves; the first
    junction is held at ``v2_start`` (or below, when braking forbids it) and the
    last one at ``v2_end``. ``smooth_v2_start``: the smoothed profile's value at
    the first junction when the plan continues an earlier one.
    """
    n = cruise_v2.shape[0]
    lim = np.empty(n + 1)
    lim[0] = v2_start
    lim[-1] = v2_end
    lim[1:-1] = np.minimum(junction_v2, np.minimum(cruise_v2[:-1], cruise_v2[1:]))
    cap = cruise_v2
    sv = None
    starts = np.ones(n, dtype=bool)
    if min_cruise_ratio > 0.0:
        lim_s = lim.copy()
        if smooth_v2_start is not None:
            lim_s[0] = min(lim[0], smooth_v2_start)
        cap, sv, owner = hump_caps(lim_s, delta * (1.0 - min_cruise_ratio), cruise_v2)
        starts[1:] = owner[1:] != owner[:-1]
        cap[0] = max(cap[0], min(v2_start, cruise_v2[0]))
        lim[1:-1] = np.minimum(lim[1:-1], np.minimum(cap[:-1], cap[1:]))
    v2 = limit_passes(lim, delta)
    cruise = np.minimum(cap, 0.5 * (v2[:-1] + v2[1:] + delta))
    cruise = np.maximum(cruise, np.maximum(v2[:-1], v2[1:]))
    return v2, cruise, sv, starts
