"""The step rate a board's axes share (protocol 3.3's STEP_BUDGET): the planner keeps the
four axes' summed peak rates under it, the device refuses a segment over it, and the cup
(whose axes never come near the AVR engine's budget) plans as without it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from cdprhost.kinematics.machine import MachineModel
from cdprhost.link.errors import StepRateError
from cdprhost.link.events import error_text
from cdprhost.motion.device_limits import STEP_RATE_MARGIN, caps_for_device
from cdprhost.motion.direct import to_wire
from cdprhost.motion.limits import Caps, move_caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.program import read_items
from cdprhost.preflight.run import preflight
from cdprhost.profile import DeviceRecord, load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.codes import ALL_AXES, ErrorCode
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.travel import SoftLimits, segment_refusal
from firmware_protocol.messages import Error
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segments import SegmentBatch, peak_step_rates
from tests.e2e.processes import square_part

CUP = Path(__file__).resolve().parents[2] / "examples" / "example.gcode"


def _refusal(deltas, total, ticks=1000, ramp=-1):
    return segment_refusal(
        ticks,
        deltas,
        ramp,
        [0, 0, 0, 0],
        homed=0,
        limits=SoftLimits(),
        clock_hz=100_000,
        max_step_rate=30_000,
        total_step_rate=total,
    )


def test_the_device_refuses_a_segment_whose_axes_add_up_to_more_than_its_budget():
    # four axes at 21,000 steps/s, each under the per-axis 30,000: 84,000 in all
    assert _refusal([210, -210, 210, 210], 80_000) == (ErrorCode.STEP_RATE, ALL_AXES, 84_000)
    assert _refusal([190, 190, -190, 190], 80_000) is None  # 76,000
    assert _refusal([210, 210, 210, 210], None) is None  # no budget: each axis alone
    # a ramp's peak is twice its mean, summed like the per-axis test: 4 x 105 -> 84,000
    assert _refusal([105, 105, 105, 105], 80_000, ramp=0)[:2] == (ErrorCode.STEP_RATE, 4)
    assert "add up to 84000/s" in error_text(Error(ErrorCode.STEP_RATE, 1, 1, ALL_AXES, 84_000))


def _peaks(path, profile, model):
    return np.concatenate(
        [
            peak_step_rates(to_wire(b), 100_000)
            for b in segment_program(
                read_items(path, profile, model), profile, model, clock_hz=100_000
            )
            if hasattr(b, "v_end")
        ]
    )


def test_planned_segments_keep_the_summed_rate_under_the_budget(tmp_path):
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    path = square_part(tmp_path / "part.gcode", layers=2)
    free = _peaks(path, profile, model)
    total = 0.5 * float(free.sum(axis=1).max())  # a budget the file's fastest moves exceed
    caps = caps_for_device(profile, None, total_step_rate=total)
    assert caps.profile.motion.max_total_step_rate == pytest.approx(STEP_RATE_MARGIN * total)
    assert caps.segments.total_step_rate == total
    capped = _peaks(path, caps.profile, model)
    assert capped.sum(axis=1).max() <= total
    assert capped.max() < free.max()  # slowed, not only merged


def test_the_cup_plans_as_without_the_engine_budget_and_a_tight_one_is_named():
    profile = load_profile("paper-prototype")

    def on(record):
        return preflight(CUP, profile.model_copy(update={"device": record}))

    per_axis = on(DeviceRecord(max_step_rate=26_000, min_segment_s=400e-6))
    budget = on(DeviceRecord(max_step_rate=26_000, min_segment_s=400e-6, total_step_rate=80_000))
    tight = on(DeviceRecord(max_step_rate=26_000, min_segment_s=400e-6, total_step_rate=40_000))
    assert budget.estimated_time_s == pytest.approx(per_axis.estimated_time_s, rel=1e-6)
    assert tight.estimated_time_s > 1.02 * per_axis.estimated_time_s
    assert tight.board is not None and "(40,000 in all)" in tight.board.message


def test_the_host_learns_the_budget_and_checks_it_before_sending():
    link = open_embedded(config=SimConfig(max_step_rate=30_000, total_step_rate=80_000))
    try:
        assert link.caps is not None and link.caps.total_step_rate == 80_000
        batch = SegmentBatch(
            np.array([1000]), np.array([[210, 210, 210, 210]]), np.array([RAMP_CONSTANT], np.int16)
        )
        with pytest.raises(StepRateError, match="add up to 84000/s"):
            link.queue_segments(batch)
    finally:
        link.close()
    plain = open_embedded(config=SimConfig(max_step_rate=30_000))
    try:
        assert plain.caps is not None and plain.caps.total_step_rate is None  # none sent
    finally:
        plain.close()


@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(*(st.floats(-60, 60),) * 2, st.floats(40, 200)),
    end=st.tuples(*(st.floats(-60, 60),) * 2, st.floats(40, 200)),
    extrusion=st.floats(0.0, 5.0),
    total=st.floats(5_000, 200_000),
)
def test_a_move_capped_by_the_budget_keeps_it_everywhere_along_it(start, end, extrusion, total):
    # the cap is bounded from samples every 10 mm; checked here every 0.5 mm along the move
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    motion = profile.motion.model_copy(update={"max_total_step_rate": total})
    steps = profile.drive.steps_per_mm
    caps = Caps.from_profile(motion, profile.extruder, steps_per_mm=steps)
    a, b = np.array(start), np.array(end)
    length = float(np.linalg.norm(b - a))
    assume(length > 1.0)
    block = MoveBlock.from_arrays(a, b, e_start=0.0, e_end=extrusion, feedrate=1e6)
    v = float(np.sqrt(move_caps(block, model.geometry.outlets, caps, chord=False).v2_cap[0]))
    u = (b - a) / length
    pts = a + np.linspace(0.0, 1.0, int(length / 0.5) + 2)[:, None] * (b - a)
    cables = pts[:, None, :] - model.geometry.outlets[None, :, :]
    cables /= np.linalg.norm(cables, axis=2, keepdims=True)
    modules = np.abs(cables @ u) @ np.asarray(steps)  # steps per mm of path, per point
    rate = v * (modules + extrusion / length * profile.extruder.steps_per_mm)
    assert rate.max() <= total * (1 + 1e-9)


def test_the_tui_and_the_service_carry_the_budget_to_the_estimate_and_the_screen():
    # the service's identity for the wire keeps the budget; a TUI on the service builds the
    # board's record from it (the preflight plans under it) and shows it
    from types import SimpleNamespace

    from cdprhost.link.events import DeviceCaps
    from cdprhost.service.device_session import identity_json
    from cdprhost.tui.control.live import identity_rows
    from cdprhost.tui.control.service_backend import announced_board

    link = open_embedded(config=SimConfig(max_step_rate=30_000, total_step_rate=80_000))
    try:
        wire = identity_json(link.identity, link.caps)
    finally:
        link.close()
    assert wire["total_step_rate"] == 80_000
    record = announced_board(wire)
    assert record is not None and record.total_step_rate == 80_000
    rows = dict(identity_rows(SimpleNamespace(**wire), "/dev/x", 250000, 80_000))
    assert rows["step budget"] == "80,000 steps/s, the axes summed"
    plain = identity_json(SimpleNamespace(**{k: wire[k] for k in wire}), DeviceCaps())
    assert "total_step_rate" not in plain
    assert "step budget" not in dict(identity_rows(SimpleNamespace(**plain), "/dev/x", 250000))
