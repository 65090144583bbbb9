"""Junction speeds follow Klipper's junction-deviation formula."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.motion.junction import junction_v2

SCV = 5.0
ACCEL = 2000.0
JD = SCV**2 * (np.sqrt(2.0) - 1.0) / ACCEL
LONG = 1000.0


def corner(angle_deg: float, kinematic=(True, True), length=LONG):
    a = np.deg2rad(angle_deg)
    unit = np.array([[1.0, 0.0, 0.0], [np.cos(a), np.sin(a), 0.0]])
    return junction_v2(unit, np.array(kinematic), np.full(2, ACCEL), np.full(2, length), JD)[0]


def test_square_corner_runs_at_square_corner_velocity():
    assert np.sqrt(corner(90.0)) == pytest.approx(SCV, rel=1e-12)


def test_straight_on_is_unlimited_and_reversal_stops():
    assert corner(0.0) == np.inf
    assert corner(180.0) == 0.0


def test_extrude_only_neighbour_meets_at_rest():
    assert corner(10.0, kinematic=(True, False)) == 0.0


@given(st.floats(1.0, 179.0))
def test_formula_at_any_angle(turn_deg):
    theta = np.deg2rad(180.0 - turn_deg)  # angle between reversed incoming and outgoing directions
    s = np.sin(theta / 2)
    expected = ACCEL * JD * s / (1 - s)
    assert corner(turn_deg) == pytest.approx(expected, rel=1e-9)


def test_short_moves_limit_the_circle_to_their_midpoints():
    d = 0.01
    theta = np.deg2rad(90.0)
    expected = 0.5 * ACCEL * d * np.tan(theta / 2)  # circle touching mid-move
    assert corner(90.0, length=d) == pytest.approx(min(expected, SCV**2), rel=1e-12)
