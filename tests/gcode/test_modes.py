"""Distance modes, units, G92 offsets, the continuous E axis, feedrates and move kinds."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode import MoveChunk, MoveKind

from .helpers import moves, read


def test_absolute_moves_fill_missing_axes():
    m = moves(read("G1 X10 Y5 Z1 F1200\nG1 X20\nG1 Y7 Z2\n"))
    np.testing.assert_array_equal(m["end"], [[10, 5, 1], [20, 5, 1], [20, 7, 2]])
    np.testing.assert_array_equal(m["start"][1:], m["end"][:-1])
    np.testing.assert_array_equal(m["feedrate"], [20.0, 20.0, 20.0])
    assert m["line"].tolist() == [1, 2, 3]


def test_relative_mode_and_back():
    m = moves(read("G1 X10 Y10 F600\nG91\nG1 X1 Y-2\nG1 X1\nG90\nG1 X0\n"))
    np.testing.assert_allclose(m["end"][:, :2], [[10, 10], [11, 8], [12, 8], [0, 8]])


def test_g91_makes_e_relative_and_g90_restores_m82():
    m = moves(read("G1 X1 E1 F600\nG91\nG1 X1 E1\nG90\nG1 X3 E3\n"))
    np.testing.assert_allclose(m["e_end"], [1, 2, 3])


def test_m83_relative_extrusion_survives_g90():
    m = moves(read("M83\nG90\nG1 X1 E0.5 F600\nG1 X2 E0.5\nG1 X3 E-1\nM82\nG1 X4 E7\n"))
    np.testing.assert_allclose(m["e_end"], [0.5, 1.0, 0.0, 7.0])


def test_g92_e_resets_keep_machine_e_continuous():
    text = "G1 X1 E5 F600\nG1 E3\nG92 E0\nG1 E2\nG1 X2 E4\nG92 E10\nG1 X3 E11\n"
    m = moves(read(text))
    np.testing.assert_allclose(m["e_start"], [0, 5, 3, 5, 7])
    np.testing.assert_allclose(m["e_end"], [5, 3, 5, 7, 8])
    np.testing.assert_allclose(m["e_end"] - m["e_start"], [5, -2, 2, 2, 1])
    k = MoveKind
    assert m["kind"].tolist() == [k.EXTRUDE, k.RETRACT, k.UNRETRACT, k.EXTRUDE, k.EXTRUDE]


def test_g92_xyz_shifts_the_programmed_frame():
    m = moves(read("G1 X10 Y10 F600\nG92 X0 Y0\nG1 X5\nG91\nG92 X100\nG1 X1\nG90\nG1 X100\n"))
    np.testing.assert_allclose(m["end"][:, 0], [10, 15, 16, 15])


def test_bare_g92_zeroes_every_axis():
    m = moves(read("G1 X10 Y4 Z1 E3 F600\nG92\nG1 X1 E1\n"))
    np.testing.assert_allclose(m["end"][1], [11, 4, 1])
    np.testing.assert_allclose(m["e_end"][1], 4)


def test_inches():
    m = moves(read("G20\nG1 X1 Y0.5 E0.1 F10\nG21\nG1 X1\n"))
    np.testing.assert_allclose(m["end"][0], [25.4, 12.7, 0])
    np.testing.assert_allclose(m["e_end"][0], 2.54)
    np.testing.assert_allclose(m["feedrate"][0], 10 * 25.4 / 60)
    np.testing.assert_allclose(m["end"][1], [1, 12.7, 0])


def test_feedrate_is_modal_and_g0_is_rapid():
    m = moves(read("G0 X1 F3000\nG1 X2\nG1 F600\nG1 X3\nG0 X4\n"))
    np.testing.assert_allclose(m["feedrate"], [50, 50, 10, 10])
    assert m["rapid"].tolist() == [True, False, False, True]
    assert m["line"].tolist() == [1, 2, 4, 5]  # the F-only line is not a move


def test_default_feedrate_before_any_f():
    m = moves(read("G1 X1\n"))
    assert m["feedrate"][0] == pytest.approx(25.0)


@pytest.mark.parametrize(
    "text, kind",
    [
        ("G1 X1 F600", MoveKind.TRAVEL),
        ("G1 X1 Z1 F600", MoveKind.TRAVEL),
        ("G1 Z1 F600", MoveKind.Z_ONLY),
        ("G1 X1 E1 F600", MoveKind.EXTRUDE),
        ("G1 E-1 F600", MoveKind.RETRACT),
        ("G1 E1 F600", MoveKind.UNRETRACT),
        ("G1 X1 E-0.5 F600", MoveKind.WIPE),
    ],
)
def test_kinds(text, kind):
    assert moves(read(text))["kind"].tolist() == [kind]


def test_zero_moves_are_dropped():
    m = moves(read("G1 X1 F600\nG1 X1\nG1 F100\nG1 X2\n"))
    assert m["line"].tolist() == [1, 4]


def test_case_and_spacing_variants_read_the_same():
    ref = moves(read("G1 X10.5 Y-2 Z0.3 E1.25 F1800\nG0 X0 Y0\n"))
    for text in (
        "g1 x10.5 y-2 z0.3 e1.25 f1800\ng0 x0 y0\n",
        "G1X10.5Y-2Z0.3E1.25F1800\nG0X0Y0\n",
        "  G1   X10.5\tY-2 Z.3 E1.2500 F1800.  \r\nG00 X0 Y0 ; home-ish\n",
        "G01 X 10.5 Y -2 Z +0.3 E1.25 F1800\nG0 X0 Y0 (paren comment)\n",
        "N1 G1 X10.5 Y-2 Z0.3 E1.25 F1800\nN2 G0 X0 Y0\n",
    ):
        got = moves(read(text))
        for key in ref:
            np.testing.assert_array_equal(got[key], ref[key], err_msg=f"{key} for {text!r}")


def test_chunks_are_bounded_and_read_only():
    text = "".join(f"G1 X{i} F600\n" for i in range(1, 1001))
    items = read(text, chunk_moves=64)
    assert all(isinstance(i, MoveChunk) and len(i) <= 64 for i in items)
    assert sum(len(i) for i in items) == 1000
    with pytest.raises(ValueError):
        items[0].start[0, 0] = 5.0


def test_blocks_do_not_change_the_result():
    text = "".join(
        f"G1 X{i % 17} Y{i % 5} E{i * 0.1:.3f} F{600 + i}\n" + ("G92 E0\n" if i % 7 == 0 else "")
        for i in range(500)
    )
    ref = moves(read(text))
    small = moves(read(text, block_lines=37))
    for key in ref:  # offsets are summed in a different order: equal to rounding
        np.testing.assert_allclose(small[key], ref[key], rtol=0, atol=1e-9)
