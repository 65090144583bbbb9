"""The host slows a print to the device's announced step rate, and says so."""

from __future__ import annotations

import numpy as np

from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.device_limits import STEP_RATE_MARGIN, caps_for_device
from cdprhost.motion.direct import to_wire
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.program import read_items
from cdprhost.profile import load_profile
from firmware_protocol.segments import peak_step_rates
from tests.e2e.processes import square_part


def test_a_profile_that_fits_is_unchanged():
    profile = load_profile("paper-prototype")
    caps = caps_for_device(profile, 10_000_000)
    assert caps.profile is profile and caps.notice is None
    assert caps_for_device(profile, None).profile is profile


def test_a_slow_device_caps_module_and_filament_speed_and_says_so():
    profile = load_profile("paper-prototype")
    rate = 0.5 * profile.motion.module_max_velocity_mm_s * max(profile.drive.steps_per_mm)
    caps = caps_for_device(profile, rate)
    assert caps.notice and "planned with" in caps.notice and "module speed" in caps.notice
    v = caps.profile.motion.module_max_velocity_mm_s
    assert v * max(profile.drive.steps_per_mm) <= STEP_RATE_MARGIN * rate + 1e-9
    assert profile.motion.module_max_velocity_mm_s > v  # the original is not touched


def test_planned_segments_stay_under_the_announced_rate(tmp_path):
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    path = square_part(tmp_path / "part.gcode", layers=2)

    def peak(p):
        out = [
            peak_step_rates(to_wire(b), 100_000).max()
            for b in segment_program(read_items(path, p, model), p, model, clock_hz=100_000)
            if hasattr(b, "v_end")
        ]
        return float(np.max(out))

    free = peak(profile)
    rate = 0.6 * free  # a device slower than this file needs
    capped = caps_for_device(profile, rate).profile
    assert peak(capped) <= rate


def _first_segments(path, profile, model, limits, n=40_000):
    """Segments of the start of ``path``'s program (commands dropped), as one wire batch."""
    from cdprhost.motion.segments import PlannedSegments

    parts, count = [], 0
    for out in segment_program(
        read_items(path, profile, model), profile, model, clock_hz=100_000, limits=limits
    ):
        if isinstance(out, PlannedSegments):
            parts.append(out)
            count += len(out)
            if count >= n:
                break
    return parts


def test_rounded_slivers_are_merged_under_the_device_rate(fixture_gcode):
    """The planner keeps speeds under 90 % of the rate, but a short piece can round to
    more steps than its time allows (5 steps in 480 us); with the device's limits such
    a segment is merged into its neighbour, keeping the steps and the time."""
    from cdprhost.motion.segments import SegmentLimits, peak_rates

    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    rate = 10_000
    capped = caps_for_device(profile, rate, 400e-6)  # the AVR's tick
    assert capped.segments == SegmentLimits(400e-6, rate)
    plain = _first_segments(fixture_gcode, capped.profile, model, SegmentLimits(400e-6, None))
    kept = _first_segments(fixture_gcode, capped.profile, model, capped.segments)
    over = np.concatenate([peak_rates(b, 100_000) for b in plain]) > rate
    assert over.any()  # the file has slivers over the rate without the limit
    for a, b in zip(plain, kept):
        assert peak_rates(b, 100_000).max() <= rate
        assert peak_step_rates(to_wire(b), 100_000).max() <= rate  # what the feed checks
        assert b.ticks.min() >= 40
        assert int(a.ticks.sum()) == int(b.ticks.sum())  # the same time
        np.testing.assert_array_equal(a.steps_abs[-1], b.steps_abs[-1])  # the same motion
        assert len(b) < len(a) or not (peak_rates(a, 100_000) > rate).any()
