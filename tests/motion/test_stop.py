"""Retiming the plan's own path to stop from speed, and to start again from rest."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.motion.segments import PlannedSegments
from cdprhost.motion.stop import (
    accelerate,
    concat_segments,
    decelerate,
    extruder_move,
    path_lengths,
)

CLOCK = 100_000
STEPS_PER_MM = 80.0


def line(n: int, spacing: float, v: float, v_first: float | None = None) -> PlannedSegments:
    """``n`` segments along x at constant planned speed ``v`` (as a cruise would be cut)."""
    x = spacing * np.arange(1, n + 1)
    point = np.column_stack([x, np.zeros(n), np.full(n, 200.0)])
    steps = np.zeros((n, 4), np.int64)
    steps[:, 0] = np.rint(x * STEPS_PER_MM)
    steps[:, 1] = -np.rint(x * STEPS_PER_MM / 2)
    steps[:, 3] = np.rint(x * 3.0)  # extruding
    delta = np.diff(steps, axis=0, prepend=np.zeros((1, 4), np.int64))
    v_end = np.full(n, v)
    v_start = np.append(v if v_first is None else v_first, v_end[:-1])
    ticks = np.full(n, int(round(spacing / v * CLOCK)))
    return PlannedSegments(
        steps,
        delta,
        ticks,
        np.full(n, 0.5),
        v_start,
        v_end,
        np.arange(n, dtype=np.int64) + 10,
        np.zeros(n, np.int32),
        point,
        x * 0.03,
        np.cumsum(ticks) / CLOCK,
    )


START = np.array([0.0, 0.0, 200.0])
ZERO = np.zeros(4, np.int64)


def _implied_accel(seg: PlannedSegments, start: np.ndarray) -> np.ndarray:
    lengths = path_lengths(start, seg.point)
    return np.abs(seg.v_end**2 - seg.v_start**2) / (2 * np.maximum(lengths, 1e-12))


@settings(max_examples=60, deadline=None)
@given(
    v0=st.floats(1.0, 200.0),
    accel=st.floats(200.0, 5000.0),
    spacing=st.floats(0.05, 5.0),
)
def test_deceleration_stops_in_v0_squared_over_2a_without_extruding(v0, accel, spacing):
    n = int(np.ceil(v0 * v0 / (2 * accel) / spacing)) + 3
    path = line(n, spacing, v0)
    out = decelerate(path, ZERO, START, v0, accel, CLOCK)
    seg = out.segments
    assert out.merged and out.count == len(seg) >= 1
    assert seg.v_start[0] == v0 and seg.v_end[-1] == 0.0
    assert np.all(np.diff(np.append(v0, seg.v_end)) <= 1e-9)  # only slows down
    assert np.all(_implied_accel(seg, START) <= accel * (1 + 1e-9))
    distance = path_lengths(START, seg.point).sum()
    assert abs(distance - v0 * v0 / (2 * accel)) < 1e-6
    seconds = seg.ticks.sum() / CLOCK
    # v0 / a, plus the rounding of ticks, plus at most half a step of the cut at its speed
    slack = len(seg) / CLOCK + 1e-9 + (2 / STEPS_PER_MM) / seg.v_start[-1]  # y: 40 steps/mm
    assert -len(seg) / CLOCK - 1e-9 <= seconds - v0 / accel <= slack
    # the cut never starts faster than the plan at that point (whole steps, rounded)
    rate0 = 2 * np.abs(seg.delta[-1, :3]) / (seg.ticks[-1] / CLOCK)
    plan_rate = np.abs(path.delta[out.count - 1, :3]) / spacing * seg.v_start[-1]
    assert np.all(rate0 <= plan_rate * (1 + 1.0 / seg.ticks[-1] + 1e-6) + 1e-9)  # +-1 tick
    assert np.all(seg.delta[:, 3] == 0)  # no extrusion
    assert np.all(seg.ticks >= 1)
    # on the planned joint-space path: the cut end lies between its neighbours' steps
    k = out.count - 1
    lo = 0 if k == 0 else path.steps_abs[k - 1, 0]
    assert lo <= seg.steps_abs[-1, 0] <= path.steps_abs[k, 0]
    assert np.array_equal(np.cumsum(seg.delta, axis=0)[-1, :3], seg.steps_abs[-1, :3])


def test_deceleration_asks_for_more_path_when_the_plan_ends_moving():
    out = decelerate(line(2, 0.1, 150.0), ZERO, START, 150.0, 1000.0, CLOCK)
    assert not out.merged


def test_deceleration_follows_a_plan_that_stops_sooner():
    path = line(40, 0.5, 100.0)
    v = np.sqrt(np.maximum(100.0**2 - 2 * 4000.0 * path_lengths(START, path.point).cumsum(), 0))
    plan = PlannedSegments(
        *(getattr(path, f) for f in ("steps_abs", "delta", "ticks", "ramp")),
        np.append(100.0, v[:-1]),
        v,
        *(getattr(path, f) for f in ("line", "layer", "point", "e", "t_end")),
    )
    out = decelerate(plan, ZERO, START, 100.0, 1000.0, CLOCK)
    assert out.merged and out.segments.v_end[-1] == 0
    assert np.all(out.segments.v_end <= plan.v_end[: out.count] + 1e-9)


@settings(max_examples=40, deadline=None)
@given(v=st.floats(5.0, 200.0), accel=st.floats(200.0, 5000.0), spacing=st.floats(0.05, 3.0))
def test_a_restart_accelerates_from_rest_and_meets_the_plan(v, accel, spacing):
    n = int(np.ceil(v * v / (2 * accel) / spacing)) + 3
    path = line(n, spacing, v)
    out = accelerate(path, START, accel, CLOCK)
    seg = out.segments
    assert out.merged and 1 <= out.count <= n
    assert seg.v_start[0] == 0.0 and seg.v_end[-1] == v  # continues exactly as planned
    assert np.all(np.diff(np.append(0.0, seg.v_end)) >= -1e-9)
    assert np.all(_implied_accel(seg, START) <= accel * (1 + 1e-9))
    assert np.array_equal(seg.delta, path.delta[: out.count])  # same path, same extrusion


def test_the_retract_and_unretract_are_extruder_only_and_cancel_out():
    pull = extruder_move(ZERO, -95, 35.0, 5000.0, 95.5, CLOCK)
    push = extruder_move(pull.steps_abs[-1], 95, 35.0, 5000.0, 95.5, CLOCK)
    both = concat_segments([pull, push])
    assert np.all(both.delta[:, :3] == 0)
    assert pull.delta[:, 3].sum() == -95 and both.steps_abs[-1, 3] == 0
    assert list(pull.ramp) == [0.0, 1.0]  # from rest, to rest
    peak = 2 * np.abs(pull.delta[:, 3]).max() / 95.5 / (pull.ticks.max() / CLOCK)
    assert peak <= 35.0 * 1.01
    assert len(extruder_move(ZERO, 0, 35.0, 5000.0, 95.5, CLOCK)) == 0
