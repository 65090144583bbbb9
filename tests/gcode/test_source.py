"""Sources (paths, line iterables, CRLF, BOM, no final newline) and the summary helper."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode import GcodeError, LayerChange, ProgramSummary, UnknownCommand, read_program

from .helpers import moves, read

TEXT = (
    "M104 S200\n;LAYER_CHANGE\n;Z:0.2\nG1 X1 Y1 Z0.2 E1 F600\nM73 P50\nG1 X2 E2\n"
    ";LAYER_CHANGE\n;Z:0.4\nG1 Z0.4\nG1 X1 E3\n"
)


@pytest.mark.parametrize(
    "raw",
    [
        TEXT.encode(),
        TEXT.replace("\n", "\r\n").encode(),
        b"\xef\xbb\xbf" + TEXT.encode(),
        TEXT.rstrip("\n").encode(),
    ],
    ids=["lf", "crlf", "bom", "no-final-newline"],
)
def test_file_variants(tmp_path, raw):
    path = tmp_path / "part.gcode"
    path.write_bytes(raw)
    items = list(read_program(path))
    assert _same(items, read(TEXT))
    s = ProgramSummary.of(items)
    assert s.layers == 2 and s.moves == 4 and s.last_line == 10


def _same(a, b) -> bool:
    ma, mb = moves(a), moves(b)
    return all(np.array_equal(ma[k], mb[k]) for k in ma) and [
        x for x in a if not hasattr(x, "start")
    ] == [x for x in b if not hasattr(x, "start")]


def test_lines_with_newlines_and_bytes():
    ref = moves(read(TEXT))
    got = moves(list(read_program(line.encode() + b"\n" for line in TEXT.splitlines())))
    for k in ref:
        np.testing.assert_array_equal(got[k], ref[k])


def test_error_names_the_path_as_given(tmp_path):
    path = tmp_path / "bad.gcode"
    path.write_text("G1 X1 F600\nG1 Y2..5\n")
    with pytest.raises(GcodeError) as exc:
        list(read_program(str(path)))
    assert str(exc.value).startswith(f"{path}:2:4: malformed number 'Y2..5' in G1")
    with pytest.raises(GcodeError, match=r"^job\.gcode:2:4: "):
        list(read_program(["G1 X1 F600", "G1 Y2..5"], name="job.gcode"))


def test_summary_totals_and_layer_lookup():
    s = ProgramSummary.of(read(TEXT))
    assert s.filament_mm == pytest.approx(3.0)
    assert s.retracted_mm == 0.0
    assert s.layer_start_lines == [2, 7]
    assert [s.layer_of_line(n) for n in (1, 2, 4, 6, 7, 10, 99)] == [-1, 0, 0, 0, 1, 1, 1]
    assert s.unknown == [UnknownCommand(5, "M73", harmless=True)]
    np.testing.assert_allclose(s.extrude_min, [0, 0, 0])
    np.testing.assert_allclose(s.extrude_max, [2, 1, 0.4])


def test_observe_passes_items_through():
    s = ProgramSummary()
    items = list(s.observe(read_program(TEXT.splitlines())))
    assert sum(isinstance(i, LayerChange) for i in items) == 2 == s.layers


def test_block_boundaries_keep_line_numbers_and_layer_heights():
    text = "G1 X1 F600\n;LAYER_CHANGE\n;Z:0.3\nG1 X2 E1\nG1 X3 E2\nG1 X4 Ybad\n"
    for block_lines in (1, 2, 3, 4, 100):
        items = []
        with pytest.raises(GcodeError) as exc:
            for item in read_program(text.splitlines(), block_lines=block_lines):
                items.append(item)
        assert (exc.value.line, exc.value.column) == (6, 7)
        assert [i for i in items if isinstance(i, LayerChange)] == [LayerChange(2, 0, 0.3)]
        assert moves(items)["line"].tolist() == [1, 4, 5]
