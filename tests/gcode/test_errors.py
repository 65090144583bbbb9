"""Malformed input: exact line and column, checksums and line numbers, file-order raising."""

from __future__ import annotations

import pytest

from cdprhost.errors import InputError
from cdprhost.gcode import Fan, GcodeError, MoveChunk, read_program

from .helpers import moves, read


def checksummed(body: str) -> str:
    cs = 0
    for b in body.encode():
        cs ^= b
    return f"{body}*{cs}"


def error_of(text: str, **kw) -> GcodeError:
    with pytest.raises(GcodeError) as exc:
        read(text, **kw)
    return exc.value


@pytest.mark.parametrize(
    "line, column, fragment",
    [
        ("G1 Xabc Y2", 4, "malformed number 'Xabc' in G1"),
        ("G1 X1.2.3", 4, "malformed number 'X1.2.3' in G1"),
        ("G1 X1 F-5", 7, "feedrate must be positive: 'F-5' in G1"),
        ("G1 X1 F0", 7, "feedrate must be positive: 'F0' in G1"),
        ("G1 X- Y2", 4, "malformed number 'X-' in G1"),
        ("G1 X1-2", 4, "malformed number 'X1-2' in G1"),
        ("G1 X.", 4, "malformed number 'X.' in G1"),
        ("G1 X", 4, "missing number after 'X' in G1"),
        ("G1 X1 X2", 7, "repeated parameter 'X2' in G1"),
        ("G2 X1 Y1 I1 P2", 13, "'P2' (full turns) is not supported in G2"),
        ("G1 X1e308", 4, "number with an exponent 'X1e308'"),
        ("G1 X1.5E+3 Y2", 4, "number with an exponent 'X1.5E+3'"),
        ("Y2 X", 4, "missing number after 'X' in a line continuing"),
        ("G1 X1 #5", 7, "unexpected character '#'"),
        ("G1 X1 (no end", 7, "unclosed '(' comment"),
        ("G1 X" + "9" * 400, 4, "out of range"),
        ("M104 Sabc", 6, "malformed number 'Sabc' in M104"),
        ("G2 X1 Y1", 1, "needs I/J"),
        ("G2 X1 Y1 I1 R2", 13, "both I/J and R"),
    ],
)
def test_malformed_parameter_names_line_and_column(line, column, fragment):
    err = error_of(f"G1 X0 Y0 F600\n; comment\n{line}\nG1 X9\n", name="part.gcode")
    assert (err.path, err.line, err.column) == ("part.gcode", 3, column)
    assert fragment in err.reason
    assert str(err).startswith(f"part.gcode:3:{column}: ")
    assert isinstance(err, InputError) and err.exit_code == 2


def test_error_raised_after_everything_before_it():
    lines = ["G1 X1 F600", "M106 S255", "G1 X2", "G1 X3 Yoops", "G1 X4"]
    got = []
    with pytest.raises(GcodeError) as exc:
        for item in read_program(lines):
            got.append(item)
    assert exc.value.line == 4
    assert isinstance(got[1], Fan)
    assert sum(len(i) for i in got if isinstance(i, MoveChunk)) == 2


def test_earliest_error_wins_across_kinds():
    # a state error (T1) before a static one (bad number) is reported first
    err = error_of("G1 X1 F600\nT1\nG1 X1.2.3\n")
    assert err.line == 2 and "single extruder" in err.reason


def test_good_checksums_and_line_numbers():
    text = "\n".join(
        checksummed(b) for b in ["N1 G1 X1 F600", "N2 G1 X2 Y3", "N3 M110 N10", "N11 G1 X4"]
    )
    m = moves(read(text))
    assert m["end"][:, 0].tolist() == [1, 2, 4]


def test_checksum_mismatch():
    body = "N1 G1 X1 F600"
    good = checksummed(body)
    bad = good[:-1] + str((int(good[-1]) + 1) % 10)
    err = error_of(f"G1 X0 F600\n{bad}\n")
    assert err.line == 2 and err.column == len(body) + 1
    assert "checksum mismatch" in err.reason


def test_line_number_gap():
    text = "\n".join(checksummed(b) for b in ["N5 G1 X1 F600", "N6 G1 X2", "N8 G1 X3"])
    err = error_of(text)
    assert err.line == 3 and "N8 out of sequence (expected N7)" in err.reason


def test_checksum_is_over_the_bytes_before_the_star():
    assert checksummed("N0 M110 N0").endswith("*125")  # the RepRap wiki example
    read(checksummed("N0 M110 N0") + "\n" + checksummed("N1 G1 X1 F600"))


def test_arc_in_other_plane():
    err = error_of("G1 X0 Y0 F600\nG18\nG2 X1 Y1 I1\n")
    assert err.line == 3 and "unsupported plane G18" in err.reason


def test_unreadable_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        list(read_program(tmp_path / "missing.gcode"))


def test_bad_arguments():
    with pytest.raises(ValueError):
        read_program([], arc_tolerance_mm=0)
    with pytest.raises(ValueError):
        read_program([], chunk_moves=0)
