"""Ramps are cut in the plan until each piece's schedule block fits a frame (block_cuts):
the pieces keep the segment's steps, time and line, and their blocks fit as the link sends
them, so no ramp falls back to the device's own stepping (the AVR's 400 us tick)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.kinematics.machine import MachineModel
from cdprhost.link.segment_feed import wire_schedules
from cdprhost.motion.block_cuts import BlockLimits, block_cuts, equal_pieces
from cdprhost.motion.device_limits import caps_for_device
from cdprhost.motion.direct import to_wire
from cdprhost.profile import load_profile
from firmware_protocol.ramp_profile import ramp_codes_from_speeds
from firmware_protocol.segment_split import block_sizes
from firmware_protocol.segments import SegmentBatch, SegmentContext, peak_step_rates
from firmware_protocol.step_schedule import reciprocal_table
from tests.motion.test_device_limits import _first_segments

CLOCK_HZ = 100_000
LIMITS = BlockLimits(160, 16.0, 8_000.0)  # the AVR engine: its tick steps 8,000/s, 120-byte frames
TABLE = reciprocal_table(160)


def _pieces(ticks, delta, vs, ve, k):
    codes = ramp_codes_from_speeds(np.array([vs]), np.array([ve]))
    _, pt, ps, speeds = equal_pieces(ticks, np.array(delta), vs, ve, int(codes[0]), k)
    return pt, ps, speeds, ramp_codes_from_speeds(speeds[:-1], speeds[1:])


@settings(max_examples=60, deadline=None)
@given(
    ticks=st.integers(80, 6000),
    delta=st.lists(st.integers(-400, 400), min_size=4, max_size=4),
    vs=st.floats(0.0, 60.0),
    ve=st.floats(0.0, 60.0),
    k=st.integers(2, 8),
)
def test_pieces_keep_the_segments_steps_time_and_speeds(ticks, delta, vs, ve, k):
    pt, ps, speeds, _ = _pieces(ticks, delta, vs, ve, k)
    assert int(pt.sum()) == ticks and (pt > 0).all()
    np.testing.assert_array_equal(ps.sum(axis=0), delta)  # every step, none twice
    # each axis moves one way, as the segment does
    assert ((ps * np.sign(delta)) >= 0).all()
    assert speeds[0] == vs and abs(speeds[-1] - ve) < 1e-9


def _cut_pieces(ticks, delta, vs, ve):
    cuts = block_cuts(
        np.array([ticks]), np.array([delta]), np.array([vs]), np.array([ve]), LIMITS, 40, CLOCK_HZ
    )
    return cuts.get(0, 1)


def test_a_long_ramp_from_rest_is_cut_until_every_piece_fits_a_frame():
    ticks, delta, vs, ve = 1500, [62, 27, -89, 1], 0.0, 30.0  # 15 ms from rest (the cup's)
    codes = ramp_codes_from_speeds(np.array([vs]), np.array([ve]))
    one = SegmentBatch(np.array([ticks]), np.array([delta]), codes)
    (whole,) = block_sizes(one, 160, 16.0, TABLE)
    assert whole == -1 or whole > LIMITS.block_bytes  # does not fit whole
    k = _cut_pieces(ticks, delta, vs, ve)
    assert k >= 2
    pt, ps, _, pc = _pieces(ticks, delta, vs, ve, k)
    batch = SegmentBatch(pt, ps, pc.astype(np.int16))
    sizes = block_sizes(batch, 160, 16.0, TABLE)
    assert ((sizes >= 0) & (sizes <= LIMITS.block_bytes)).all(), sizes
    # and the link sends each piece with its block (none left to the device's stepping)
    sent = wire_schedules(batch, SegmentContext(), 16, 120)
    moving = {(i, a) for i in range(k) for a in range(4) if ps[i, a]}
    assert moving <= set(sent)


def test_a_short_or_steady_segment_is_left_whole():
    assert _cut_pieces(400, [10, -4, 3, 0], 20.0, 22.0) == 1  # a short ramp: a small block
    assert _cut_pieces(4000, [800, -300, 100, 5], 30.0, 30.0) == 1  # steady: predicted


def test_the_plan_for_a_block_device_cuts_ramps_and_keeps_time_and_motion(fixture_gcode):
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    plain = caps_for_device(profile, 26_000, 400e-6)
    cut = caps_for_device(profile, 26_000, 400e-6, LIMITS)
    a_parts = _first_segments(fixture_gcode, plain.profile, model, plain.segments, n=2500)
    b_parts = _first_segments(fixture_gcode, cut.profile, model, cut.segments, n=2500)
    assert sum(len(b) for b in b_parts) > sum(len(a) for a in a_parts)  # some ramps were cut
    ctx = SegmentContext()
    for a, b in zip(a_parts, b_parts):
        assert int(a.ticks.sum()) == int(b.ticks.sum())  # the same time
        np.testing.assert_array_equal(a.steps_abs[-1], b.steps_abs[-1])  # the same motion
        np.testing.assert_allclose(a.t_end[-1], b.t_end[-1])
        # every move still ends on a segment end with its absolute steps
        assert set(map(tuple, a.steps_abs[np.r_[np.diff(a.line) != 0, True]])) <= set(
            map(tuple, b.steps_abs)
        )
        assert b.ticks.min() >= 40
        # a restart from any row sets the extruder to its E's rounding: the steps it stood at
        spm = profile.extruder.steps_per_mm
        if (np.rint(a.e * spm) == a.steps_abs[:, 3]).all():
            np.testing.assert_array_equal(np.rint(b.e * spm), b.steps_abs[:, 3])
        wire = to_wire(b)
        fast = peak_step_rates(wire, CLOCK_HZ).max(axis=1) > LIMITS.profile_step_rate
        ramps = np.flatnonzero((wire.ramps != -1) & fast)
        sent = wire_schedules(wire[ramps[0] : ramps[-1] + 1], ctx, 16, 120) if ramps.size else {}
        for i in ramps.tolist():
            # no ramp axis faster than the device's own stepping left without its block
            for axis in np.flatnonzero(wire.deltas[i]).tolist():
                assert (i - ramps[0], axis) in sent, (i, axis)


def test_only_a_board_whose_own_stepping_is_slower_gets_its_ramps_cut():
    """STEPPING (3.1) reaches the plan: a device that steps every axis alike (the model's
    default, a 3.0 device) gets no cuts; one whose profile stepping is slower than its
    schedules (the AVR's engine: 8,000 under 26,000) gets them, for its ramps over 8,000."""
    from cdprhost.machine.board_limits import block_limits
    from cdprhost.sim.embedded import open_embedded
    from firmware_protocol.device.config import SimConfig

    for config, want in (
        (SimConfig(max_step_rate=26_000), None),
        (SimConfig(max_step_rate=26_000, profile_step_rate=8_000), 8_000.0),
    ):
        link = open_embedded(config=config)
        try:
            limits = block_limits(link.identity, link.caps)
        finally:
            link.close()
        assert (limits and limits.profile_step_rate) == want
        if limits is not None:
            assert (limits.cycles_per_tick, limits.block_bytes) == (160, 120 - 27)
