"""What the simulated device refuses of a segment's schedules on receipt (PROTOCOL.md 5.5)."""

from __future__ import annotations

from unittest.mock import patch

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.device import schedules as device_schedules
from firmware_protocol.device.schedules import schedule_refusal
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.schedule_fit import fit_axis
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    AxisSchedule,
    Chunk,
    device_edges,
    ideal_edges,
    predictable,
    predicted,
    predicted_error,
    reciprocal_table,
)

CPT = 160
TABLE = reciprocal_table(CPT)


def _refusal(ticks, deltas, ramp, explicit, tol=16, shortest=127):
    return schedule_refusal(
        ticks,
        deltas,
        ramp,
        explicit,
        cycles_per_tick=CPT,
        tol_cycles=tol,
        min_interval_cycles=shortest,
        table=TABLE,
    )


def test_a_fitted_block_and_predicted_axes_run():
    fitted = fit_axis(ideal_edges(30, 2000, 0, CPT), 16)
    assert (
        _refusal(
            2000,
            (30, 7, -3, 0),
            0,
            {
                0: fitted,
                1: fit_axis(ideal_edges(7, 2000, 0, CPT), 16),
                2: fit_axis(ideal_edges(3, 2000, 0, CPT), 16),
            },
        )
        is None
    )
    assert _refusal(2000, (30, 7, -3, 1), -1, {}) is None  # all predicted


def test_an_axis_it_cannot_predict_without_a_block_runs_on_its_own_stepping():
    assert _refusal(2000, (30, 0, 0, 0), 255, {}) is None


def test_a_block_that_strays_is_refused_with_its_worst_error():
    good = fit_axis(ideal_edges(30, 2000, 0, CPT), 16)
    late = AxisSchedule(good.lead + (40 << FRAC_BITS), good.chunks)  # every edge 40 late
    axis, value = _refusal(2000, (30, 0, 0, 0), 0, {0: late})
    assert axis == 0 and 40 - 16 <= value <= 40 + 16 + 1


def test_a_block_outside_the_segment_or_too_fast_is_refused():
    # the prediction's interval, first edge at the segment's very end
    pred = predicted(10, 1000, TABLE)
    outside = AxisSchedule(1000 * CPT << FRAC_BITS, pred.chunks)
    axis, value = _refusal(1000, (0, 0, 10, 0), -1, {2: outside})
    assert axis == 2 and value >= 1000 * CPT
    fast = AxisSchedule(0, (Chunk(10, 100 << FRAC_BITS, 0),))
    assert _refusal(1000, (0, 0, 10, 0), -1, {2: fast}, shortest=127) == (2, 100)
    assert _refusal(1000, (0, 0, 0, 10), -1, {3: AxisSchedule(0, (Chunk(9, 500, 0),))}) == (3, 9)


def test_counts_that_do_not_add_up_are_refused_with_the_first_chunks_count():
    sched = AxisSchedule(0, (Chunk(-2, 16_000 << FRAC_BITS, 0), Chunk(12, 16_000 << FRAC_BITS, 0)))
    assert _refusal(100_000, (10, 0, 0, 0), -1, {0: sched}) == (0, -2)


def _array_form_checks(ticks, deltas, ramp, tol):
    """The axes whose edges the device must check, by the array functions of
    step_schedule.py (the device model once ran these on every segment)."""
    n = np.asarray(deltas, dtype=np.int64)
    ok = predictable(n, np.full(4, ticks), np.full(4, ramp if ramp >= 0 else RAMP_CONSTANT))
    bound = predicted_error(n, np.full(4, ticks), TABLE, CPT)
    return [k for k in range(4) if ok[k] and bound[k] > tol]


@settings(max_examples=300, deadline=None)
@given(
    st.integers(40, 70_000),
    st.lists(st.integers(-1100, 1100), min_size=4, max_size=4),
    st.sampled_from([-1, -1, 0, 128, 255]),
    st.sampled_from([0, 1, 2, 16]),
)
def test_the_device_checks_the_edges_of_exactly_the_predictions_the_bound_does_not_clear(
    ticks, deltas, ramp, tol
):
    """An axis predicted within the tolerance in closed form, or not predictable, is not
    edge-checked; every other predicted axis is, and a stray edge refuses the segment."""
    checked = _array_form_checks(ticks, deltas, ramp, tol)
    with patch.object(device_schedules, "device_edges", side_effect=device_edges) as edges:
        refused = _refusal(ticks, tuple(deltas), ramp, {}, tol=tol)
    assert edges.call_count == (len(checked) if refused is None else checked.index(refused[0]) + 1)
    if refused is not None:
        assert refused[0] in checked and refused[1] > tol
