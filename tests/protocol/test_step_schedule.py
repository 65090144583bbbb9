"""Step schedules: every edge the device would issue within tolerance, counts exact."""

from __future__ import annotations

from unittest.mock import patch

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol import schedule_fit, step_schedule
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.schedule_fit import fit_axis, plan_schedules
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    MAX_COUNT,
    AxisSchedule,
    Chunk,
    ScheduleError,
    check_segment,
    cycles_per_tick,
    device_edges,
    device_times,
    ideal_edges,
    predictable,
    predictable_one,
    predicted,
    predicted_error,
    predicted_error_one,
    reciprocal_table,
    schedule_error,
    shortest_interval,
)
from tests.protocol.step_schedule_reference import reference_fit_axis

CPT = 160  # 16 MHz over the 100 kHz protocol clock
TABLE = reciprocal_table(CPT)


def _most_steps(ticks: int, code: int, max_rate: float) -> int:
    r = 0.5 if code < 0 else code / 255
    return int(max_rate * ticks / 100_000 / max(2 * r, 2 - 2 * r))


def segments(max_rate: float = 100_000.0):
    """(steps, ticks, ramp code) of one axis, no faster than ``max_rate`` steps/s at its
    peak (the device refuses faster ones)."""

    def build(ticks: int, code: int, share: float, sign: int) -> tuple[int, int, int]:
        return sign * max(1, int(share * _most_steps(ticks, code, max_rate))), ticks, code

    return st.builds(
        build,
        st.integers(40, 20_000),
        st.integers(-1, 255),
        st.floats(0.0, 1.0),
        st.sampled_from([1, -1]),
    )


def batches(max_rate: float = 100_000.0, max_segments: int = 6):
    """A few segments of four axes (some still, some reversed; ramps and constant speed),
    each axis no faster than ``max_rate`` steps/s at its peak."""

    def build(ticks: int, code: int, shares: list[float], signs: list[int]):
        most = _most_steps(ticks, code, max_rate)
        return ticks, [sign * int(share * most) for share, sign in zip(shares, signs)], code

    one = st.builds(
        build,
        st.integers(40, 12_000),
        st.integers(-1, 255) | st.sampled_from([0, 255]),
        st.lists(st.floats(0.0, 1.0) | st.just(0.0), min_size=4, max_size=4),
        st.lists(st.sampled_from([1, -1]), min_size=4, max_size=4),
    )
    return st.lists(one, min_size=1, max_size=max_segments).map(
        lambda segs: SegmentBatch(
            np.array([t for t, _, _ in segs]),
            np.array([d for _, d, _ in segs]),
            np.array([c for _, _, c in segs], dtype=np.int16),
        )
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


@settings(max_examples=300, deadline=None)
@given(
    st.integers(1, 1024),
    st.integers(1, 0xFFFF),
    st.sampled_from([1, -1]),
    st.sampled_from([80, 160]),
)
def test_one_axis_bound_is_the_arrays_bound_to_the_bit(steps, ticks, sign, cpt):
    """The device model's scalar bound (every received segment's axes) is the array
    version's float, not merely close to it."""
    table = reciprocal_table(cpt)
    n = sign * steps
    one = predicted_error_one(n, ticks, table, cpt)
    assert one == float(predicted_error(np.array([n]), np.array([ticks]), table, cpt)[0])


def test_a_constant_speed_axis_within_the_table_is_predicted_to_within_a_cycle():
    steps = np.array([1, 16, 330, 1024])
    ticks = np.array([40, 50, 3000, 60_000])
    assert predicted_error(steps, ticks, TABLE, CPT).max() <= 1.0


def test_what_the_device_cannot_predict():
    steps, ticks = [5, 5, 0, 1025, 5], [100, 100, 100, 100, 70_000]
    codes = [RAMP_CONSTANT, 0, RAMP_CONSTANT, RAMP_CONSTANT, RAMP_CONSTANT]
    ok = predictable(np.array(steps), np.array(ticks), np.array(codes))
    assert ok.tolist() == [True, False, False, False, False]
    assert [predictable_one(*a) for a in zip(steps, ticks, codes)] == ok.tolist()


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


@settings(max_examples=150, deadline=None)
@given(segments(), st.sampled_from([1.0, 16.0, 40.0]))
def test_the_fitter_needs_no_more_chunks_than_the_first_one_on_the_same_edges(seg, tol):
    steps, ticks, code = seg
    ideal = ideal_edges(steps, ticks, code, CPT)
    sched = fit_axis(ideal, tol)
    reference = reference_fit_axis(ideal, tol)
    assert len(sched.chunks) <= len(reference.chunks)
    assert sched.lead == reference.lead
    assert np.abs(schedule_error(sched, ideal)).max() <= tol


@settings(max_examples=100, deadline=None)
@given(batches(), st.sampled_from([16.0, 40.0]))
def test_a_batch_planned_at_once_holds_every_edge_of_every_axis_it_sends(batch, tol):
    """Every axis of the batch fitted together: each schedule still issues exactly ``|n|``
    edges, strictly increasing, inside its segment and within the tolerance, in no more
    chunks than the first fitter took for that axis alone."""
    explicit = plan_schedules(batch, CPT, tol, TABLE)
    for i in range(len(batch)):
        ticks, code = int(batch.ticks[i]), int(batch.ramps[i])
        mine = {k: s for (j, k), s in explicit.items() if j == i}
        assert check_segment(batch.deltas[i], ticks, code, mine, CPT, tol, TABLE) <= tol
        for k, sched in mine.items():
            edges = device_edges(sched)
            assert np.all(np.diff(edges) > 0)
            ideal = ideal_edges(int(batch.deltas[i, k]), ticks, code, CPT)
            assert len(sched.chunks) <= len(reference_fit_axis(ideal, tol).chunks)


def test_a_batch_planned_at_once_is_each_axis_fitted_alone():
    # axes of very different lengths (1, 2, 3 edges; a long ramp) advance together
    batch = SegmentBatch(
        np.array([3000, 40, 9000, 500]),
        np.array([[300, -1, 2, 0], [3, 0, 0, -2], [4200, 150, -1, 7], [60, 59, 1, 0]]),
        np.array([0, 128, 255, 40], dtype=np.int16),
    )
    explicit = plan_schedules(batch, CPT, 16.0, TABLE)
    assert len(explicit) == 12
    for (i, k), sched in explicit.items():
        ideal = ideal_edges(int(batch.deltas[i, k]), int(batch.ticks[i]), int(batch.ramps[i]), CPT)
        assert sched == fit_axis(ideal, 16.0)


def test_a_chunk_holds_at_most_a_u16_count_of_edges():
    # constant speed, beyond the table: one recurrence would do, a count cannot
    ideal = ideal_edges(150_000, 60_000, RAMP_CONSTANT, CPT)
    sched = fit_axis(ideal, 16.0)
    assert [c.count for c in sched.chunks] == [MAX_COUNT, MAX_COUNT, 150_000 - 2 * MAX_COUNT]
    assert np.abs(schedule_error(sched, ideal)).max() <= 16.0


def test_a_long_ramp_from_rest_takes_no_more_chunks_than_the_first_fitter_took():
    # hundreds of edges a chunk late in the ramp: the search tries a few levels of a
    # bisection at once there rather than whole ranges of counts
    ideal = ideal_edges(20_000, 40_000, 0, CPT)
    for tol in (16.0, 80.0):
        sched = fit_axis(ideal, tol)
        assert len(sched.chunks) <= len(reference_fit_axis(ideal, tol).chunks)
        assert max(c.count for c in sched.chunks) > 300
        assert np.abs(schedule_error(sched, ideal)).max() <= tol


@settings(max_examples=40, deadline=None)
@given(batches(max_segments=12), st.sampled_from([16.0, 40.0]))
def test_the_searches_replayed_in_numpy_find_what_they_find_one_axis_at_a_time(batch, tol):
    # many axes fitting at once replay their searches in numpy (down to a few, which go on
    # one by one): forced here from the first round, whatever the batch's size
    with patch.object(schedule_fit, "_FEW_AXES", 0):
        explicit = plan_schedules(batch, CPT, tol, TABLE)
    for (i, k), sched in explicit.items():
        ideal = ideal_edges(int(batch.deltas[i, k]), int(batch.ticks[i]), int(batch.ramps[i]), CPT)
        assert sched == fit_axis(ideal, tol)
        assert np.abs(schedule_error(sched, ideal)).max() <= tol


def test_a_batch_of_many_ramps_takes_no_more_chunks_than_each_axis_alone_took():
    rng = np.random.default_rng(7)
    m = 30
    ticks = rng.integers(200, 4000, m)
    codes = rng.integers(0, 256, m).astype(np.int16)
    deltas = (rng.uniform(-0.6, 0.6, (m, 4)) * ticks[:, None]).astype(np.int64)
    explicit = plan_schedules(SegmentBatch(ticks, deltas, codes), CPT, 16.0, TABLE)
    assert len(explicit) == int((deltas != 0).sum()) > schedule_fit._FEW_AXES
    for i in range(m):
        mine = {k: s for (j, k), s in explicit.items() if j == i}
        assert check_segment(deltas[i], int(ticks[i]), int(codes[i]), mine, CPT, 16.0, TABLE) <= 16
        for k, sched in mine.items():
            ideal = ideal_edges(int(deltas[i, k]), int(ticks[i]), int(codes[i]), CPT)
            assert len(sched.chunks) <= len(reference_fit_axis(ideal, 16.0).chunks)


def test_the_ideal_edges_of_a_batch_are_those_of_each_axis_to_the_last_bit():
    steps = np.array([1, 7, 300, 2])
    ticks = np.array([40, 1000, 60_000, 3])
    codes = np.array([-1, 0, 128, 255])
    many = step_schedule.ideal_edges_many(steps, ticks, codes, CPT)
    alone = [ideal_edges(int(n), int(d), int(c), CPT) for n, d, c in zip(steps, ticks, codes)]
    assert np.array_equal(many, np.concatenate(alone))
