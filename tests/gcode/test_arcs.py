"""G2/G3: I/J and R forms, full circles, helices, and the chord tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.gcode import GcodeError, MoveKind

from .helpers import moves, read


def arc_moves(text: str, tol: float = 0.01) -> dict:
    m = moves(read(text, arc_tolerance_mm=tol))
    return m


def assert_on_arc(m, centre, radius, tol):
    """Chord ends on the circle; chord midpoints no further than ``tol`` inside it."""
    c = np.asarray(centre)
    ends = np.linalg.norm(m["end"][:, :2] - c, axis=1)
    np.testing.assert_allclose(ends, radius, atol=1e-9)
    mids = np.linalg.norm((m["start"][:, :2] + m["end"][:, :2]) / 2 - c, axis=1)
    assert np.all(radius - mids <= tol + 1e-12)
    assert np.all(radius - mids >= 0)


def test_ccw_quarter_with_ij():
    m = arc_moves("G1 X10 Y0 F600\nG3 X0 Y10 I-10 J0\n")
    arc = {k: v[1:] for k, v in m.items()}
    assert_on_arc(arc, (0, 0), 10, 0.01)
    np.testing.assert_allclose(arc["end"][-1], [0, 10, 0])
    # counter-clockwise: through the first quadrant
    assert np.all(arc["end"][:, 0] >= -1e-9) and np.all(arc["end"][:, 1] >= -1e-9)
    assert np.all(np.diff(np.arctan2(arc["end"][:, 1], arc["end"][:, 0])) > 0)
    assert set(arc["line"].tolist()) == {2}


def test_cw_quarter_with_ij():
    m = arc_moves("G1 X10 Y0 F600\nG2 X0 Y-10 I-10 J0\n")
    arc = {k: v[1:] for k, v in m.items()}
    assert_on_arc(arc, (0, 0), 10, 0.01)
    assert np.all(arc["end"][:, 1] <= 1e-9)
    assert np.all(np.diff(np.arctan2(arc["end"][:, 1], arc["end"][:, 0])) < 0)


def test_segment_count_matches_tolerance():
    r, tol = 10.0, 0.01
    m = arc_moves("G1 X10 Y0 F600\nG3 X0 Y10 I-10 J0\n", tol)
    step = 2 * math.acos(1 - tol / r)
    assert len(m["line"]) - 1 == math.ceil((math.pi / 2) / step)


@pytest.mark.parametrize("cmd, r", [("G2", 5), ("G2", -5), ("G3", 5), ("G3", -5)])
def test_r_form_half_circle(cmd, r):
    m = arc_moves(f"G1 X0 Y0 F600\n{cmd} X10 Y0 R{r}\n")
    arc = {k: v[1:] for k, v in m.items()}
    assert_on_arc(arc, (5, 0), 5, 0.01)


def test_r_form_short_and_long_way():
    short = arc_moves("G1 X0 Y0 F600\nG2 X10 Y0 R10\n")
    long = arc_moves("G1 X0 Y0 F600\nG2 X10 Y0 R-10\n")
    h = math.sqrt(100 - 25)
    # G2 with R > 0: centre to the right of the chord (below), the arc bulges up by 10 - h
    assert_on_arc({k: v[1:] for k, v in short.items()}, (5, -h), 10, 0.01)
    assert_on_arc({k: v[1:] for k, v in long.items()}, (5, h), 10, 0.01)
    assert short["end"][1:, 1].max() == pytest.approx(10 - h, abs=0.01)
    assert long["end"][1:, 1].max() == pytest.approx(10 + h, abs=0.02)  # over the top, the long way
    assert len(long["line"]) > 3 * len(short["line"])


def test_r_form_equals_ij_form():
    a = arc_moves("G1 X3 Y4 F600\nG3 X-4 Y3 R5\n")
    b = arc_moves("G1 X3 Y4 F600\nG3 X-4 Y3 I-3 J-4\n")
    np.testing.assert_allclose(a["end"], b["end"], atol=1e-9)


def test_full_circle():
    m = arc_moves("G1 X10 Y0 F600\nG2 X10 Y0 I-10 J0 E5\n")
    arc = {k: v[1:] for k, v in m.items()}
    assert_on_arc(arc, (0, 0), 10, 0.01)
    length = np.linalg.norm(arc["end"] - arc["start"], axis=1).sum()
    assert length == pytest.approx(2 * math.pi * 10, rel=1e-3)  # chords are a little shorter
    np.testing.assert_allclose(arc["end"][-1], [10, 0, 0])
    assert arc["e_end"][-1] == pytest.approx(5)
    assert np.all(arc["kind"] == MoveKind.EXTRUDE)


def test_helix_interpolates_z_and_e_with_angle():
    m = arc_moves("G1 X10 Y0 Z0 F600\nG3 X-10 Y0 Z2 I-10 J0 E4\n")
    arc = {k: v[1:] for k, v in m.items()}
    angle = np.unwrap(np.arctan2(arc["end"][:, 1], arc["end"][:, 0]))
    np.testing.assert_allclose(arc["end"][:, 2], 2 * angle / math.pi, atol=1e-9)
    np.testing.assert_allclose(arc["e_end"], 4 * angle / math.pi, atol=1e-9)


def test_relative_arc():
    m = arc_moves("G1 X10 Y10 F600\nG91\nG2 X10 Y0 I5 J0\n")
    arc = {k: v[1:] for k, v in m.items()}
    assert_on_arc(arc, (15, 10), 5, 0.01)
    np.testing.assert_allclose(arc["end"][-1], [20, 10, 0])


def test_end_off_the_circle_is_refused():
    with pytest.raises(GcodeError) as exc:
        read("G1 X10 Y0 F600\nG3 X0 Y12 I-10 J0\n")
    assert exc.value.line == 2 and "not on the circle" in exc.value.reason


def test_radius_too_small_is_refused():
    with pytest.raises(GcodeError) as exc:
        read("G1 X0 Y0 F600\nG2 X10 Y0 R2\n")
    assert exc.value.line == 2 and "too small" in exc.value.reason


@given(
    cx=st.floats(-50, 50),
    cy=st.floats(-50, 50),
    r=st.floats(0.5, 80),
    a0=st.floats(-math.pi, math.pi),
    sweep=st.floats(0.05, 2 * math.pi - 0.05),
    cw=st.booleans(),
    tol=st.sampled_from([0.001, 0.01, 0.05]),
)
def test_tolerance_holds_for_any_arc(cx, cy, r, a0, sweep, cw, tol):
    a1 = a0 - sweep if cw else a0 + sweep
    x0, y0 = cx + r * math.cos(a0), cy + r * math.sin(a0)
    x1, y1 = cx + r * math.cos(a1), cy + r * math.sin(a1)
    text = f"G1 X{x0:.6f} Y{y0:.6f} F600\n{'G2' if cw else 'G3'} X{x1:.6f} Y{y1:.6f} I{cx - x0:.6f} J{cy - y0:.6f}\n"
    m = arc_moves(text, tol)
    on_arc = m["line"] == 2  # the G1 to the start is no move when the start is the origin
    arc = {k: v[on_arc] for k, v in m.items()}
    # radius is blended between the (rounded) start and end radii: allow that rounding
    ends = np.linalg.norm(arc["end"][:, :2] - (cx, cy), axis=1)
    np.testing.assert_allclose(ends, r, atol=2e-6)
    mids = np.linalg.norm((arc["start"][:, :2] + arc["end"][:, :2]) / 2 - (cx, cy), axis=1)
    assert np.all(r - mids <= tol + 2e-6)
    turned = np.abs(
        np.diff(
            np.unwrap(
                np.arctan2(np.r_[y0, arc["end"][:, 1]] - cy, np.r_[x0, arc["end"][:, 0]] - cx)
            )
        )
    )
    assert turned.sum() == pytest.approx(sweep, abs=1e-4)
