"""Planner: trapezoids within the limits, cornering, stops, bounded streaming lookahead."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.motion.moves import MoveBlock, drop_noops

from .helpers import concat_planned, path_block, plan_all, triangle_corners


def random_path(seed: int, n: int, step: float) -> np.ndarray:
    """A random walk inside the build volume (machine frame), steps of about ``step`` mm."""
    rng = np.random.default_rng(seed)
    p = [np.array([0.0, 0.0, 150.0])]
    for _ in range(n):
        q = p[-1] + rng.normal(size=3) * step * np.array([1.0, 1.0, 0.2])
        q[:2] = np.clip(q[:2], -35, 35)
        q[2] = np.clip(q[2], 115, 300)
        p.append(q)
    return np.array(p)


def test_long_move_is_a_trapezoid_at_max_speed(sim_profile, sim_model):
    block = path_block([[0, -50, 150], [0, 50, 150]], feedrate=300.0)
    parts, planner = plan_all(block, sim_profile, sim_model, module_limits=False)
    p = concat_planned(parts)
    assert p["v_cruise"][0] == pytest.approx(200.0)
    assert p["v_start"][0] == 0.0 and p["v_end"][0] == 0.0
    assert planner.time == pytest.approx(100 / 200 + 200 / 2000, rel=1e-12)


def test_retraction_uses_the_extruder_limits(sim_profile, sim_model):
    block = MoveBlock.from_arrays([0, 0, 150], [0, 0, 150], 5.0, 3.0, feedrate=40.0)
    _, planner = plan_all(block, sim_profile, sim_model)
    a = sim_profile.extruder.max_accel_mm_s2
    assert planner.time == pytest.approx(2.0 / 40.0 + 40.0 / a, rel=1e-12)


def test_square_corners_at_square_corner_velocity(sim_profile, sim_model):
    c = np.array([[-30, -30], [30, -30], [30, 30], [-30, 30], [-30, -30]], float)
    pts = np.column_stack([c, np.full(5, 150.0)])
    parts, _ = plan_all(path_block(pts, feedrate=100.0), sim_profile, sim_model)
    p = concat_planned(parts)
    np.testing.assert_allclose(
        p["v_end"][:-1], sim_profile.motion.square_corner_velocity_mm_s, rtol=1e-9
    )
    np.testing.assert_allclose(p["v_start"][1:], p["v_end"][:-1])
    assert p["v_end"][-1] == 0.0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.3, 2.0, 15.0]), st.sampled_from([0.0, 0.5]))
def test_plans_stay_within_limits(sim_profile, sim_model, seed, step, ratio):
    pts = random_path(seed, 150, step)
    feed = np.random.default_rng(seed).uniform(5, 300, len(pts) - 1)
    block = path_block(pts, feedrate=1.0)
    block = drop_noops(
        MoveBlock(block.start, block.end, block.e_start, block.e_end, feed, block.line, block.layer)
    )
    feed = block.feedrate
    parts, _ = plan_all(block, sim_profile, sim_model, module_limits=False, min_cruise_ratio=ratio)
    p = concat_planned(parts)
    m = sim_profile.motion
    tol = 1e-9
    assert p["v_start"][0] == 0.0 and p["v_end"][-1] == 0.0
    assert np.all(p["v_cruise"] <= np.minimum(feed, m.max_velocity_mm_s) * (1 + tol))
    assert np.all(p["accel"] <= m.max_accel_mm_s2)
    phases = (2 * p["v_cruise"] ** 2 - p["v_start"] ** 2 - p["v_end"] ** 2) / (2 * p["accel"])
    assert np.all(phases <= p["length"] * (1 + 1e-9) + 1e-9)
    np.testing.assert_allclose(p["v_start"][1:], p["v_end"][:-1], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(p["t_start"][1:], p["t_start"][:-1] + p["duration"][:-1], rtol=1e-12)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.5, 3.0]))
def test_bounded_lookahead_equals_planning_at_once(sim_profile, sim_model, seed, step):
    pts = random_path(seed, 400, step)
    block = path_block(pts, feedrate=120.0, e_per_mm=0.03)
    whole, planner_a = plan_all(block, sim_profile, sim_model, pieces=1, batch_moves=10**6)
    streamed, planner_b = plan_all(block, sim_profile, sim_model, pieces=25, batch_moves=16)
    a, b = concat_planned(whole), concat_planned(streamed)
    assert len(streamed) > 1  # it really committed in several steps
    assert planner_b.stats.start_speed_drops == 0
    np.testing.assert_allclose(b["v_start"], a["v_start"], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b["v_cruise"], a["v_cruise"], rtol=1e-6, atol=1e-6)
    assert planner_b.time == pytest.approx(planner_a.time, rel=1e-9)


def test_module_limits_slow_moves_along_a_cable(sim_profile, sim_model):
    # a move straight along cable 3's direction: its slider moves as fast as the effector
    outlet = sim_model.geometry.outlets[2]
    a = np.array([0.0, 0.0, 200.0])
    u = (a - outlet) / np.linalg.norm(a - outlet)
    block = path_block([a, a + 80 * u], feedrate=200.0)
    parts, planner = plan_all(block, sim_profile, sim_model)
    assert parts[0].module_limited[0]
    assert parts[0].v_cruise[0] <= sim_profile.motion.module_max_velocity_mm_s * 1.0001
    assert planner.stats.module_limited == 1


def test_triangle_corners_fit(sim_profile):
    c = triangle_corners()
    assert np.all(np.abs(c) < 100)
