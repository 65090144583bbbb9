"""Vectorised lookahead passes against straightforward sequential references."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from cdprhost.motion.lookahead import hump_caps, limit_passes, plan_profile

speeds2 = st.floats(0.0, 40000.0, allow_nan=False)
deltas = st.floats(0.0, 20000.0, allow_nan=False)


def sequential_passes(lim, delta):
    v = np.array(lim, dtype=float)
    for j in range(len(v) - 2, -1, -1):
        v[j] = min(v[j], v[j + 1] + delta[j])
    for j in range(1, len(v)):
        v[j] = min(v[j], v[j - 1] + delta[j - 1])
    return v


def klipper_peaks(lim, smooth_delta, cruise):
    """Per-move peak cruise v^2 of Klipper's flush (non-lazy), written out sequentially."""
    n = len(cruise)
    max_smoothed = np.empty(n)
    prev = 0.0
    for i in range(n):  # forward: what the smoothed profile can reach
        max_smoothed[i] = min(lim[i], prev) if i else lim[0]
        prev = max_smoothed[i] + smooth_delta[i]
    peaks = np.full(n, np.nan)
    delayed: list[int] = []
    next_smoothed = lim[n]
    peak = 0.0
    for i in range(n - 1, -1, -1):
        reachable = next_smoothed + smooth_delta[i]
        smoothed = min(max_smoothed[i], reachable)
        # Ties within rounding (1e-9 relative) count as equal, as in hump_caps: which side
        # of a one-ulp tie a move falls on is not a property of the plan.
        tol = 1e-9 * max(reachable, 1.0)
        if smoothed < reachable - tol:
            if smoothed + smooth_delta[i] > next_smoothed + tol or delayed:
                peak = min(cruise[i], (smoothed + reachable) * 0.5)
                for j in delayed:
                    peaks[j] = peak
                delayed = []
            peaks[i] = peak
        else:
            delayed.append(i)
        next_smoothed = smoothed
    return peaks


@given(
    st.integers(1, 40).flatmap(
        lambda n: st.tuples(
            arrays(float, n + 1, elements=speeds2), arrays(float, n, elements=deltas)
        )
    )
)
def test_limit_passes_match_sequential(case):
    lim, delta = case
    np.testing.assert_allclose(
        limit_passes(lim, delta), sequential_passes(lim, delta), rtol=1e-9, atol=1e-6
    )


@given(
    st.integers(2, 40).flatmap(
        lambda n: st.tuples(
            arrays(float, n - 1, elements=speeds2),
            arrays(float, n, elements=st.floats(1.0, 40000.0)),
            arrays(float, n, elements=st.floats(1.0, 20000.0)),
        )
    ),
    st.sampled_from([0.0, 0.5]),
)
def test_profile_is_feasible(case, ratio):
    jv2, cruise_cap, delta = case
    v2, cruise, _, _ = plan_profile(jv2, cruise_cap, delta, 0.0, 0.0, min_cruise_ratio=ratio)
    tol = 1e-6 * (1.0 + v2.max())
    assert v2[0] == 0.0 and v2[-1] == 0.0
    assert np.all(v2[1:-1] <= jv2 + tol)
    assert np.all(np.abs(np.diff(v2)) <= delta + tol)
    assert np.all(cruise <= cruise_cap + tol)
    assert np.all(cruise >= np.maximum(v2[:-1], v2[1:]) - tol)
    # accelerating to cruise and braking from it fits in the move
    assert np.all((2 * cruise - v2[:-1] - v2[1:]) <= delta + tol)


@given(
    st.integers(2, 30).flatmap(
        lambda n: st.tuples(
            arrays(float, n + 1, elements=speeds2),
            arrays(float, n, elements=st.floats(1.0, 10000.0)),
            arrays(float, n, elements=st.floats(1.0, 40000.0)),
        )
    )
)
def test_hump_caps_match_klipper_grouping(case):
    lim, smooth_delta, cruise = case
    lim = lim.copy()
    lim[0] = 0.0
    lim[-1] = 0.0
    lim[1:-1] = np.minimum(lim[1:-1], np.minimum(cruise[:-1], cruise[1:]))
    ref = klipper_peaks(lim, smooth_delta, cruise)
    mine, _, _ = hump_caps(lim, smooth_delta, cruise)
    known = np.isfinite(ref)
    np.testing.assert_allclose(mine[known], np.minimum(cruise, ref)[known], rtol=1e-7, atol=1e-6)


def test_smoothing_lowers_peaks_of_short_zigzags():
    n = 20
    delta = np.full(
        n, 2 * 2000 * 0.5
    )  # 0.5 mm moves at 2000 mm/s^2: 10 mm, never reaching 200 mm/s
    jv2 = np.full(n - 1, 1e9)
    cap = np.full(n, 200.0**2)
    _, plain, _, _ = plan_profile(jv2, cap, delta, 0.0, 0.0, min_cruise_ratio=0.0)
    _, smooth, _, _ = plan_profile(jv2, cap, delta, 0.0, 0.0, min_cruise_ratio=0.5)
    assert smooth.max() <= plain.max() + 1e-9
    assert plain.max() == np.float64(2 * 2000 * 5.0)  # full acceleration to the middle
    assert smooth.max() < 0.6 * plain.max()  # the hump peaks where half the acceleration gets
