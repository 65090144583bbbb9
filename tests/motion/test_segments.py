"""Segmenter: chord tolerance, absolute steps, ticks, phase splits, module limits in joint space."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.kinematics import MachineModel
from cdprhost.motion.segments import DEFAULT_CLOCK_HZ, piece_positions
from cdprhost.profile import MachineProfile

from .helpers import (
    concat_batches,
    concat_planned,
    path_block,
    plan_all,
    segment_all,
    triangle_corners,
)


def long_moves(seed: int, n: int = 12) -> np.ndarray:
    """Points far apart across the build volume, corners and top included."""
    rng = np.random.default_rng(seed)
    corners = triangle_corners(170.0 * 0.85)
    w = rng.dirichlet([0.4, 0.4, 0.4], size=n)
    xy = w @ corners
    z = rng.uniform(112, 300, n)
    return np.column_stack([xy, z])


def run(profile, model, pts, feedrate=150.0, e_per_mm=0.04):
    block = path_block(pts, feedrate=feedrate, e_per_mm=e_per_mm)
    parts, planner = plan_all(block, profile, model)
    batches, seg = segment_all(parts, profile, model, start_point=pts[0])
    return block, concat_planned(parts), concat_batches(batches), planner, seg


def line_distance(points, a, b):
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    r = points - a
    return np.linalg.norm(r - np.einsum("ij,ij->i", r, u)[:, None] * u, axis=1)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from(["sim", "proto"]))
def test_joint_space_midpoints_stay_within_the_chord_tolerance(
    sim_profile, proto_profile, seed, which
):
    profile = sim_profile if which == "sim" else proto_profile
    model = MachineModel.from_profile(profile)
    block, _, seg, _, _ = run(profile, model, long_moves(seed))
    s = model.ik(seg["point"])
    prev = np.vstack([model.ik(block.start[:1]), s[:-1]])
    mid = model.fk(0.5 * (prev + s))
    move = seg["line"] - 1
    dev = line_distance(mid, block.start[move], block.end[move])
    assert dev.max() <= profile.motion.chord_tolerance_mm
    assert dev.max() > 0.2 * profile.motion.chord_tolerance_mm  # not wastefully short either


def test_move_ends_are_segment_ends_with_absolute_steps(sim_profile, sim_model):
    block, plan, seg, _, segmenter = run(sim_profile, sim_model, long_moves(3))
    last = np.flatnonzero(np.diff(np.append(seg["line"], -1)) != 0)
    np.testing.assert_array_equal(seg["point"][last], block.end)
    np.testing.assert_array_equal(
        seg["steps_abs"][last, :3], sim_model.steps(sim_model.ik(block.end))
    )
    np.testing.assert_array_equal(
        seg["steps_abs"][last, 3], np.rint(block.e_end * sim_profile.extruder.steps_per_mm)
    )
    start = np.append(sim_model.steps(sim_model.ik(block.start[:1]))[0], 0)
    np.testing.assert_array_equal(seg["delta"].sum(axis=0), seg["steps_abs"][-1] - start)
    np.testing.assert_array_equal(segmenter.state.steps, seg["steps_abs"][-1])


def test_ticks_add_up_to_the_planned_time(sim_profile, sim_model):
    _, plan, seg, planner, _ = run(sim_profile, sim_model, long_moves(5))
    f = DEFAULT_CLOCK_HZ
    assert abs(seg["ticks"].sum() - planner.time * f) <= 1.0
    t_begin = np.append(0.0, seg["t_end"][:-1])
    assert np.all(np.abs(seg["ticks"] - (seg["t_end"] - t_begin) * f) <= 1.0)
    assert np.all(seg["ticks"] > 0)


def test_segments_have_speed_linear_in_time(sim_profile, sim_model):
    block, plan, seg, _, _ = run(sim_profile, sim_model, long_moves(7))
    prev = np.vstack([block.start[:1], seg["point"][:-1]])
    length = np.linalg.norm(seg["point"] - prev, axis=1)
    dt = np.diff(np.append(0.0, seg["t_end"]))
    np.testing.assert_allclose(
        length, 0.5 * (seg["v_start"] + seg["v_end"]) * dt, rtol=1e-6, atol=2e-4
    )
    # one acceleration per segment: +a, 0 or -a (phases are never mixed)
    accel = (seg["v_end"] - seg["v_start"]) / dt
    a = plan["accel"][seg["line"] - 1]
    ratio = np.abs(accel) / a
    assert np.all((ratio < 1e-6) | (np.abs(ratio - 1) < 1e-6))
    np.testing.assert_allclose(seg["ramp"], seg["v_start"] / (seg["v_start"] + seg["v_end"]))


def test_phase_boundaries_split_moves(sim_profile, sim_model):
    parts, _ = plan_all(
        path_block([[0, -40, 150], [0, 40, 150]], feedrate=150.0), sim_profile, sim_model
    )
    x = piece_positions(parts[0]).x
    d_acc = 150.0**2 / (2 * parts[0].accel[0])
    assert np.any(np.isclose(x, d_acc)) and np.any(np.isclose(x, 80.0 - d_acc))
    assert x[-1] == 80.0


def tight_profile(profile: MachineProfile) -> MachineProfile:
    motion = profile.motion.model_copy(
        update={"module_max_velocity_mm_s": 40.0, "module_max_accel_mm_s2": 400.0}
    )
    return profile.model_copy(update={"motion": motion})


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31))
def test_module_limits_hold_in_joint_space(sim_profile, seed):
    profile = tight_profile(sim_profile)
    model = MachineModel.from_profile(profile)
    block, plan, seg, planner, _ = run(profile, model, long_moves(seed), feedrate=200.0)
    assert planner.stats.module_limited > 0
    s = model.ik(seg["point"])
    prev_s = np.vstack([model.ik(block.start[:1]), s[:-1]])
    prev_p = np.vstack([block.start[:1], seg["point"][:-1]])
    length = np.linalg.norm(seg["point"] - prev_p, axis=1)
    rate = (s - prev_s) / length[:, None]  # ds/dl of each segment
    vmax = profile.motion.module_max_velocity_mm_s
    amax = profile.motion.module_max_accel_mm_s2
    assert np.abs(rate * np.maximum(seg["v_start"], seg["v_end"])[:, None]).max() <= vmax * 1.001
    dt = np.diff(np.append(0.0, seg["t_end"]))
    within = np.abs(rate * ((seg["v_end"] - seg["v_start"]) / dt)[:, None])
    assert within.max() <= amax * 1.001
    # finite differences of joint velocity between segment mid-times of the same move (the J-dot part too)
    vel_mid = rate * (0.5 * (seg["v_start"] + seg["v_end"]))[:, None]
    t_mid = seg["t_end"] - 0.5 * dt
    same = seg["line"][1:] == seg["line"][:-1]
    fd = np.abs(np.diff(vel_mid, axis=0) / np.diff(t_mid)[:, None])[same]
    assert fd.max() <= amax * 1.02


def test_backlash_directions_carry_across_batches(sim_profile):
    data = sim_profile.model_dump()
    data["effects"] = {"backlash": {"beta": [0.05, -0.03, 0.04]}}
    profile = MachineProfile.model_validate(data)
    model = MachineModel.from_profile(profile)
    pts = long_moves(11, n=20)
    block = path_block(pts, feedrate=120.0)
    parts, _ = plan_all(block, profile, model, batch_moves=10**6)
    whole = concat_batches(segment_all(parts, profile, model, start_point=pts[0])[0])
    halves = [parts[0].take(slice(0, 7)), parts[0].take(slice(7, None))]
    split = concat_batches(segment_all(halves, profile, model, start_point=pts[0])[0])
    np.testing.assert_array_equal(split["steps_abs"], whole["steps_abs"])
    assert not np.array_equal(
        whole["steps_abs"][:, :3], model.steps(model.ik(whole["point"]))
    )  # backlash acts


def test_home_resets_the_step_counters(sim_profile, sim_model):
    from cdprhost.motion.segments import Segmenter

    seg = Segmenter(
        sim_model, sim_profile.drive.home_mm, e_steps_per_mm=sim_profile.extruder.steps_per_mm
    )
    np.testing.assert_array_equal(seg.state.steps, [0, 0, 0, 0])
    np.testing.assert_allclose(seg.state.point, sim_model.home_point(np.zeros(3)))
    assert seg.state.point[2] == pytest.approx(327.34, abs=0.01)


def test_tiny_moves_never_make_empty_segments(sim_profile, sim_model):
    pts = np.array(
        [[0, 0, 150], [0, 20, 150], [0, 20 + 2e-6, 150], [0, 20 + 4e-6, 150], [0, 40, 150]], float
    )
    block, plan, seg, planner, _ = run(sim_profile, sim_model, pts, feedrate=200.0)
    assert np.all(seg["ticks"] >= 1)
    np.testing.assert_array_equal(
        seg["steps_abs"][-1, :3], sim_model.steps(sim_model.ik(pts[-1:]))[0]
    )
    np.testing.assert_array_equal(
        np.cumsum(seg["delta"], axis=0)[-1],
        seg["steps_abs"][-1] - seg["steps_abs"][0] + seg["delta"][0],
    )
    assert abs(seg["ticks"].sum() - planner.time * DEFAULT_CLOCK_HZ) <= 1.0


def test_extrude_only_moves_are_cut_at_their_phases(sim_profile, sim_model):
    from cdprhost.motion.moves import MoveBlock

    p = np.array([0.0, 0.0, 150.0])
    block = MoveBlock.from_arrays(
        [p, p], [p, p], [0.0, -6.0], [-6.0, 0.0], feedrate=40.0
    )  # retract, prime
    parts, planner = plan_all(block, sim_profile, sim_model)
    seg = concat_batches(segment_all(parts, sim_profile, sim_model, start_point=p)[0])
    de = np.abs(np.diff(np.append(0.0, seg["e"])))
    dt = np.diff(np.append(0.0, seg["t_end"]))
    np.testing.assert_allclose(de, 0.5 * (seg["v_start"] + seg["v_end"]) * dt, rtol=1e-9, atol=1e-9)
    assert len(seg["ticks"]) == 6  # accelerate, cruise, brake for each
    assert np.all(seg["delta"][:, :3] == 0)
    assert seg["delta"][:, 3].sum() == 0 and seg["delta"][:3, 3].sum() == -round(6 * 95.5)


def test_fixture_pipeline_is_consistent(fixture_gcode, sim_profile, sim_model):
    from cdprhost.motion.pipeline import PipelineTotals, segment_program
    from cdprhost.motion.program import read_items
    from cdprhost.motion.segments import PlannedSegments

    totals = PipelineTotals()
    ticks = 0
    steps = np.zeros(4, dtype=np.int64)
    last = None
    for out in segment_program(
        read_items(fixture_gcode, sim_profile, sim_model), sim_profile, sim_model, totals=totals
    ):
        if isinstance(out, PlannedSegments):
            assert out.ticks.min() >= 1 and out.ramp.min() >= 0.0 and out.ramp.max() <= 1.0
            ticks += int(out.ticks.sum())
            steps += out.delta.sum(axis=0)
            np.testing.assert_array_equal(
                steps, out.steps_abs[-1]
            )  # no homing inside the print body
            last = out
        elif type(out).__name__ == "HomeCommand":
            steps[:3] = 0
    assert totals.moves == 122769
    # each move's duration is rounded on its own (so a move's segments do not depend on when
    # the program reached it): within half a tick per move, 4.3 ms over these 122,769 moves
    assert abs(ticks / DEFAULT_CLOCK_HZ - totals.planned_time_s) < 0.1e-6 * totals.moves
    np.testing.assert_array_equal(
        last.steps_abs[-1, :3], sim_model.steps(sim_model.ik(last.point[-1:]))[0]
    )
