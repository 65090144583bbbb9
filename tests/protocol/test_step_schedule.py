"""Step schedules: every edge the device would issue within tolerance, counts exact."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.segments import RAMP_CONSTANT, SegmentBatch
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    AxisSchedule,
    Chunk,
    ScheduleError,
    check_segment,
    cycles_per_tick,
    device_edges,
    device_times,
    fit_axis,
    ideal_edges,
    plan_schedules,
    predictable,
    predicted,
    predicted_error,
    reciprocal_table,
    schedule_error,
    shortest_interval,
)

CPT = 160  # 16 MHz over the 100 kHz protocol clock
TABLE = reciprocal_table(CPT)


def segments(max_rate: float = 100_000.0):
    """(steps, ticks, ramp code) of one axis, no faster than ``max_rate`` steps/s at its
    peak (the device refuses faster ones)."""

    def build(ticks: int, code: int, share: float, sign: int) -> tuple[int, int, int]:
        r = 0.5 if code < 0 else code / 255
        peak_per_tick = max(2 * r, 2 - 2 * r)
        most = int(max_rate * ticks / 100_000 / peak_per_tick)
        return sign * max(1, int(share * most)), ticks, code

    return st.builds(
        build,
        st.integers(40, 20_000),
        st.integers(-1, 255),
        st.floats(0.0, 1.0),
        st.sampled_from([1, -1]),
    )


@settings(max_examples=150, deadline=None)
@given(segments(), st.sampled_from([16.0, 40.0, 80.0]))
def test_every_edge_of_a_fitted_schedule_lies_within_its_tolerance_and_the_count_is_exact(seg, tol):
    steps, ticks, code = seg
    ideal = ideal_edges(steps, ticks, code, CPT)
    sched = fit_axis(ideal, tol)
    assert sched.count == abs(steps)
    err = schedule_error(sched, ideal)
    assert np.abs(err).max() <= tol
    edges = device_edges(sched)
    assert np.all(np.diff(edges) > 0)
    assert edges[0] >= 0 and edges[-1] <= ticks * CPT


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 1024), st.integers(1, 0xFFFF))
def test_the_closed_form_bound_of_a_prediction_holds_for_its_every_edge(steps, ticks):
    ideal = ideal_edges(steps, ticks, RAMP_CONSTANT, CPT)
    sched = predicted(steps, ticks, TABLE)
    worst = float(np.abs(schedule_error(sched, ideal)).max())
    bound = float(predicted_error(np.array([steps]), np.array([ticks]), TABLE, CPT)[0])
    assert worst <= bound + 1e-9
    assert bound - worst <= 1.0  # and it is tight: no schedule sent that was not needed


def test_a_constant_speed_axis_within_the_table_is_predicted_to_within_a_cycle():
    steps = np.array([1, 16, 330, 1024])
    ticks = np.array([40, 50, 3000, 60_000])
    assert predicted_error(steps, ticks, TABLE, CPT).max() <= 1.0


def test_what_the_device_cannot_predict():
    ok = predictable(
        np.array([5, 5, 0, 1025, 5]),
        np.array([100, 100, 100, 100, 70_000]),
        np.array([RAMP_CONSTANT, 0, RAMP_CONSTANT, RAMP_CONSTANT, RAMP_CONSTANT]),
    )
    assert ok.tolist() == [True, False, False, False, False]


def test_a_ramp_from_rest_needs_several_chunks_and_each_edge_still_holds():
    ideal = ideal_edges(700, 11_000, 0, CPT)
    sched = fit_axis(ideal, 16.0)
    assert len(sched.chunks) > 1
    assert sched.count == 700
    assert np.abs(schedule_error(sched, ideal)).max() <= 16.0


def test_plan_schedules_sends_only_what_the_device_cannot_predict():
    batch = SegmentBatch(
        np.array([3000, 3000, 3000]),
        np.array([[300, -150, 0, 7], [300, 200, 2000, 0], [300, 0, 0, 0]]),
        np.array([0, RAMP_CONSTANT, 255], dtype=np.int16),
    )
    explicit = plan_schedules(batch, CPT, 16.0)
    # the ramps' moving axes, and the constant segment's axis beyond the table (2000 steps
    # are 1024 + more)
    assert set(explicit) == {(0, 0), (0, 1), (0, 3), (1, 2), (2, 0)}
    for (i, k), sched in explicit.items():
        ideal = ideal_edges(int(batch.deltas[i, k]), 3000, int(batch.ramps[i]), CPT)
        assert np.abs(schedule_error(sched, ideal)).max() <= 16.0


def test_a_schedule_that_issues_another_number_of_edges_is_refused():
    ideal = ideal_edges(10, 1000, RAMP_CONSTANT, CPT)
    short = AxisSchedule(0, (Chunk(9, 16_000 << FRAC_BITS, 0),))
    with pytest.raises(ValueError, match="9 edges for 10 steps"):
        schedule_error(short, ideal)


def test_tolerance_below_a_cycle_and_a_clock_that_does_not_divide_are_refused():
    with pytest.raises(ValueError, match="at least 1"):
        fit_axis(ideal_edges(10, 1000, RAMP_CONSTANT, CPT), 0.5)
    with pytest.raises(ValueError, match="whole multiple"):
        cycles_per_tick(30_000)


def test_a_device_runs_a_predicted_axis_and_refuses_what_it_cannot_run():
    deltas = np.array([300, -20, 0, 3])
    # the ramp's axes carry schedules; the constant one is predicted
    ramp = {k: fit_axis(ideal_edges(int(d), 3000, 0, CPT), 16.0) for k, d in enumerate(deltas) if d}
    assert check_segment(deltas, 3000, 0, ramp, CPT, 16.0, TABLE) <= 16.0
    assert check_segment(deltas, 3000, RAMP_CONSTANT, {}, CPT, 16.0, TABLE) <= 1.0
    partial = {0: ramp[0], 1: ramp[1]}
    with pytest.raises(ScheduleError, match="axis 3: 3 steps with no schedule"):
        check_segment(deltas, 3000, 0, partial, CPT, 16.0, TABLE)
    # the constant segment's schedule sent for a ramp: the edges stray
    wrong = dict(ramp)
    wrong[0] = predicted(300, 3000, TABLE)
    with pytest.raises(ScheduleError, match="axis 0: an edge .* cycles from its time"):
        check_segment(deltas, 3000, 0, wrong, CPT, 16.0, TABLE)
    short = dict(ramp)
    short[1] = AxisSchedule(0, (Chunk(19, 1000 << FRAC_BITS, 0),))
    with pytest.raises(ScheduleError, match="axis 1: the schedule issues 19 of 20 steps"):
        check_segment(deltas, 3000, 0, short, CPT, 16.0, TABLE)
    late = dict(ramp)
    late[3] = AxisSchedule(3000 * CPT << FRAC_BITS, (Chunk(3, 1 << FRAC_BITS, 0),))
    with pytest.raises(ScheduleError, match="axis 3: an edge falls outside the segment"):
        check_segment(deltas, 3000, 0, late, CPT, 16.0, TABLE)


@settings(max_examples=100, deadline=None)
@given(segments())
def test_the_shortest_interval_is_the_shortest_gap_between_edges(seg):
    steps, ticks, code = seg
    sched = fit_axis(ideal_edges(steps, ticks, code, CPT), 16.0)
    gaps = np.diff(device_times(sched))
    assert shortest_interval(sched) == (gaps.min() if len(gaps) else 0)
