"""Program level: homing, command order, which commands stop the motion, the whole pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode import DwellCommand, Fan, HomeCommand, LayerChange, SetTemperature
from cdprhost.motion.pipeline import PipelineTotals, segment_program
from cdprhost.motion.program import (
    ProgramPlanner,
    flushes_motion,
    home_position,
    plan_program,
    read_items,
)
from cdprhost.motion.segments import PlannedSegments
from cdprhost.motion.trapezoid import PlannedMoves

PROGRAM = [
    "G28",  # 1
    "G1 X0 Y0 Z10 F6000",  # 2
    "G1 X20 Y0 F3000",  # 3
    "M106 S255",  # 4 fan: keeps moving
    "G1 X20 Y20",  # 5
    "G4 P500",  # 6 dwell: stops
    "G1 X0 Y20",  # 7
    ";LAYER_CHANGE",  # 8
    ";Z:10.3",  # 9
    "G1 Z10.3",  # 10
    "M109 S210",  # 11 wait: stops
    "G1 X0 Y0 E1 F1200",  # 12
    "G28 X0",  # 13 homes everything
    "G1 X5 Y5 Z5 F3000",  # 14
]


def planned_and_commands(profile, model, lines=PROGRAM):
    return list(plan_program(read_items(lines, profile, model), profile, model))


def test_commands_keep_their_place_between_moves(sim_profile, sim_model):
    out = planned_and_commands(sim_profile, sim_model)
    order = []
    for item in out:
        if isinstance(item, PlannedMoves):
            order += [("move", int(x)) for x in item.moves.line]
        else:
            order.append((type(item).__name__, item.line))
    lines = [ln for _, ln in order]
    assert lines == sorted(lines)
    assert ("Fan", 4) in order and ("DwellCommand", 6) in order and ("HomeCommand", 13) in order


def test_flushing_commands_stop_the_machine_and_others_do_not(sim_profile, sim_model):
    out = planned_and_commands(sim_profile, sim_model)
    for i, item in enumerate(out):
        if isinstance(item, PlannedMoves) or i == 0:
            continue
        before = next((o for o in reversed(out[:i]) if isinstance(o, PlannedMoves)), None)
        if before is None:
            continue
        if flushes_motion(item):
            assert before.v_end[-1] == 0.0, item
        elif isinstance(item, Fan):
            assert before.v_end[-1] > 0.0  # the corner at line 5 is taken at speed, not stopped
    assert (
        flushes_motion(DwellCommand(1, 0.5))
        and flushes_motion(HomeCommand(1))
        and flushes_motion(SetTemperature(1, "hotend", 200, True))
    )
    assert not flushes_motion(SetTemperature(1, "hotend", 200, False)) and not flushes_motion(
        LayerChange(1, 1, None)
    )


def test_moves_start_at_the_home_point_after_homing(sim_profile, sim_model):
    out = planned_and_commands(sim_profile, sim_model)
    moves = [o for o in out if isinstance(o, PlannedMoves)]
    home = home_position(sim_profile, sim_model)
    first = moves[0].moves
    np.testing.assert_allclose(first.start[0], home)
    after = next(m for m in moves if m.moves.line[0] == 14).moves
    np.testing.assert_allclose(after.start[0], home)
    np.testing.assert_allclose(after.end[0], [5, 5, 115])


def test_dwell_time_is_counted(sim_profile, sim_model):
    def total(lines):
        pp = ProgramPlanner(sim_profile, sim_model)
        for item in read_items(lines, sim_profile, sim_model):
            pp.moves(item) if hasattr(item, "start") else pp.command(item)
        pp.finish()
        return pp.time

    with_wait = [
        ("M400" if ln.startswith("G4") else ln) for ln in PROGRAM
    ]  # stops too, but no pause
    assert total(PROGRAM) - total(with_wait) == pytest.approx(0.5, abs=1e-9)


def test_pipeline_segments_and_homing_reset(sim_profile, sim_model):
    totals = PipelineTotals()
    out = list(
        segment_program(
            read_items(PROGRAM, sim_profile, sim_model), sim_profile, sim_model, totals=totals
        )
    )
    batches = [o for o in out if isinstance(o, PlannedSegments)]
    assert totals.segments == sum(len(b) for b in batches) and totals.moves == 7
    # the batch right after the second G28 starts from the endstop steps (0, 0, 0)
    after = next(b for b in batches if b.line[0] == 14)
    first_target = sim_model.steps(sim_model.ik(after.point[:1]))[0]
    np.testing.assert_array_equal(after.delta[0, :3], first_target - 0)
    ticks = sum(int(b.ticks.sum()) for b in batches)
    assert (
        abs(ticks / 1e6 - (totals.planned_time_s - 0.5)) <= len(PROGRAM) * 1e-6
    )  # dwell is not a segment


def test_encode_hook_sees_every_batch(sim_profile, sim_model):
    seen = []
    out = list(
        segment_program(
            read_items(PROGRAM, sim_profile, sim_model),
            sim_profile,
            sim_model,
            encode=lambda b: seen.append(len(b)) or ("encoded", len(b)),
        )
    )
    assert seen and all(isinstance(o, tuple) or not isinstance(o, PlannedSegments) for o in out)


def test_pipeline_keeps_commands_between_the_segments_of_their_moves(sim_profile, sim_model):
    lines = []
    program = PROGRAM + [
        "G1 X30 Y30 F3000",
        "M106 S128",
        "G1 X0 Y30",
        ";LAYER_CHANGE",
        "G1 Z12",
        "G1 X0 Y0",
    ]
    for out in segment_program(read_items(program, sim_profile, sim_model), sim_profile, sim_model):
        lines += [int(x) for x in out.line] if isinstance(out, PlannedSegments) else [out.line]
    assert lines == sorted(lines)
    assert 4 in lines and program.index("M106 S128") + 1 in lines  # the two fans


def test_segment_blocks_marks_match_the_ordered_stream(sim_profile, sim_model):
    from cdprhost.motion.pipeline import SegmentBlock, segment_blocks

    program = PROGRAM + ["G1 X30 Y30 F3000", "M106 S128", "G1 X0 Y30", "G1 X0 Y0"]
    ordered = list(
        segment_program(read_items(program, sim_profile, sim_model), sim_profile, sim_model)
    )
    blocks = list(
        segment_blocks(
            read_items(program, sim_profile, sim_model),
            sim_profile,
            sim_model,
            encode=len,
        )
    )
    flat = [p for b in blocks for p in (b.split() if isinstance(b, SegmentBlock) else [b])]
    assert [type(x).__name__ for x in flat] == [type(x).__name__ for x in ordered]
    for a, b in zip(flat, ordered):
        if isinstance(a, PlannedSegments):
            np.testing.assert_array_equal(a.steps_abs, b.steps_abs)
            np.testing.assert_array_equal(a.delta, b.delta)
        else:
            assert a == b
    marked = [b for b in blocks if isinstance(b, SegmentBlock) and b.marks]
    assert marked and all(b.encoded == len(b.batch) for b in blocks if isinstance(b, SegmentBlock))
    fan_block = next(
        b for b in marked if any(isinstance(c, Fan) and c.line == 16 for _, c in b.marks)
    )
    cut = next(k for k, c in fan_block.marks if isinstance(c, Fan) and c.line == 16)
    assert fan_block.batch.line[cut - 1] == 15 and fan_block.batch.line[cut] == 17
