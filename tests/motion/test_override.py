"""Speed and flow overrides on planned segments (pure): the same path and steps, other times,
within the acceleration, speed and step-rate limits."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.limits import Caps
from cdprhost.motion.override import FlowEpoch, check_percent, retime, scale_flow
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.prepared import prepare
from cdprhost.motion.segments import PlannedSegments, SegmentLimits
from cdprhost.profile import load_profile

CLOCK = 100_000
LIMITS = SegmentLimits(400e-6, None)


def _square_layers(tmp_path, layers=3):
    lines = ["G28", "G92 E0"]
    e = 0.0
    for n in range(layers):
        lines.append(f"G1 Z{0.3 * (n + 1):.2f} F3000")
        for x, y in [(20, 0), (20, 20), (0, 20), (0, 0)] * 2:
            e += 0.8
            lines.append(f"G1 X{x} Y{y} E{e:.3f} F2400")
        lines += [f"G1 E{e - 1:.3f} F2400", f"G1 E{e:.3f}"]
    path = tmp_path / "square.gcode"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    path = _square_layers(tmp_path_factory.mktemp("override"))
    batches = [
        out
        for out in segment_program(
            prepare(path, profile, model).items(), profile, model, clock_hz=CLOCK, limits=LIMITS
        )
        if isinstance(out, PlannedSegments) and len(out) > 50
    ]
    caps = Caps.from_profile(profile.motion, profile.extruder, profile.statics.a_max_mm_s2)
    return batches[0], caps, model, profile


def _cut(batch: PlannedSegments, at: int):
    """The batch after segment ``at``: (rest, start point, speed there)."""
    return batch.take(slice(at + 1, len(batch))), batch.point[at], float(batch.v_end[at])


def _retimed(planned, factor, at=40, flow=1.0):
    batch, caps, model, profile = planned
    rest, start, v0 = _cut(batch, at)
    out = retime(
        rest,
        factor,
        start_point=start,
        v0=v0,
        caps=caps,
        outlets=model.geometry.outlets,
        clock_hz=CLOCK,
        limits=LIMITS,
        flow=flow,
        e_steps_per_mm=profile.extruder.steps_per_mm,
    )
    return rest, start, v0, out


def _accel(seg: PlannedSegments, start: np.ndarray) -> np.ndarray:
    ends = np.vstack([start[None, :], seg.point])
    length = np.linalg.norm(np.diff(ends, axis=0), axis=1)
    moving = length > 1e-6
    return np.abs(seg.v_end**2 - seg.v_start**2)[moving] / (2 * length[moving])


@pytest.mark.parametrize("factor", [0.5, 2.0, 5.0])
def test_a_speed_override_keeps_the_path_the_steps_and_the_acceleration_limit(planned, factor):
    rest, start, v0, out = _retimed(planned, factor)
    new = out.batch
    assert np.array_equal(new.steps_abs, rest.steps_abs)  # same path, same steps
    assert np.array_equal(new.delta, rest.delta)
    assert new.v_start[0] == pytest.approx(v0)  # continues the motion already sent
    assert new.v_end[-1] <= rest.v_end[-1] + 1e-9  # the next batch starts from its plan
    caps = planned[1]
    assert _accel(new, start).max() <= caps.max_accel * 1.001
    assert new.v_end.max() <= caps.max_velocity + 1e-6
    assert np.all(new.ticks >= 1)
    # planned stops stay stops (extruder-only retractions keep their plan)
    assert np.all(new.v_end[rest.v_end <= 1e-9] <= 1e-9)


def test_twice_the_speed_shortens_the_time_and_half_doubles_it(planned):
    _, _, _, fast = _retimed(planned, 2.0)
    _, _, _, slow = _retimed(planned, 0.5)
    _, _, _, same = _retimed(planned, 1.0)
    assert same.ratio == pytest.approx(1.0, abs=0.01)
    assert 0.5 <= fast.ratio < 0.8  # accelerations and corners keep it above a half
    assert slow.ratio == pytest.approx(2.0, rel=0.05)


def test_the_device_step_rate_caps_the_override(planned):
    batch, caps, model, profile = planned
    rest, start, v0 = _cut(batch, 40)
    rate = 6000.0
    out = retime(
        rest,
        5.0,
        start_point=start,
        v0=min(v0, 1.0),
        caps=caps,
        outlets=model.geometry.outlets,
        clock_hz=CLOCK,
        limits=SegmentLimits(400e-6, rate),
    )
    new = out.batch
    peak = (
        np.abs(new.delta).max(axis=1)
        / (new.ticks / CLOCK)
        * np.maximum(1.0, 2 * np.maximum(new.ramp, 1 - new.ramp))
    )
    moving = np.linalg.norm(np.diff(np.vstack([start, new.point]), axis=0), axis=1) > 1e-6
    assert peak[moving & (np.abs(new.delta[:, 3]) < 1)].max() <= rate * 1.02


def test_flow_scales_the_extruder_steps_after_the_change_and_keeps_the_axis_continuous(planned):
    batch = planned[0]
    rest, _, _ = _cut(batch, 40)
    prev = batch.steps_abs[40].copy()
    epoch = FlowEpoch().changed(1.5, int(prev[3]), int(prev[3]))
    scaled = scale_flow(rest, epoch, prev)
    fed = scaled.steps_abs[:, 3] - prev[3]
    planned_fed = rest.steps_abs[:, 3] - prev[3]
    assert np.all(np.abs(fed - 1.5 * planned_fed) <= 0.5 + 1e-9)
    assert np.array_equal(scaled.steps_abs[:, :3], rest.steps_abs[:, :3])
    assert np.array_equal(np.cumsum(scaled.delta, axis=0) + prev, scaled.steps_abs)
    assert np.array_equal(scaled.e, rest.e)  # the program's filament positions (resume)


@pytest.mark.parametrize("percent", [0, 9, 501, 9999, float("nan")])
def test_an_override_out_of_range_is_refused(percent):
    with pytest.raises(ValueError, match="out of range"):
        check_percent("speed", percent)


def test_an_override_in_range_is_a_factor():
    assert check_percent("flow", 95) == pytest.approx(0.95)
