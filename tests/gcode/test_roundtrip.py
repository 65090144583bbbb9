"""Property tests: formatted moves read back exactly; the fast tokenizer agrees with the exact parser."""

from __future__ import annotations

import re

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.gcode.line_parser import parse_line
from cdprhost.gcode.tokenize import tokenize

from .helpers import moves, read

coord = st.floats(-500, 500, allow_nan=False, allow_infinity=False)
style = st.fixed_dictionaries(
    {
        "decimals": st.integers(0, 6),
        "lower": st.booleans(),
        "glued": st.booleans(),
        "lead": st.sampled_from(["", " ", "\t"]),
        "strip_zero": st.booleans(),
    }
)


def fmt(v: float, decimals: int, strip_zero: bool) -> str:
    s = f"{v:.{decimals}f}"
    if strip_zero:
        s = re.sub(r"^(-?)0\.", r"\1.", s)  # PrusaSlicer writes .35 and -.5
    return s


@given(
    st.lists(
        st.tuples(coord, coord, coord, st.floats(0, 50), st.floats(1, 20000)),
        min_size=1,
        max_size=40,
    ),
    style,
)
def test_formatted_moves_round_trip(points, s):
    lines, expected = [], []
    e_total = 0.0
    for x, y, z, de, f in points:
        words = [fmt(v, s["decimals"], s["strip_zero"]) for v in (x, y, z)]
        e_total += de
        ew = f"{e_total:.5f}"
        fw = f"{max(f, 1):.1f}"
        parts = [f"X{words[0]}", f"Y{words[1]}", f"Z{words[2]}", f"E{ew}", f"F{fw}"]
        sep = "" if s["glued"] else " "
        line = s["lead"] + "G1" + sep + sep.join(parts)
        lines.append(line.lower() if s["lower"] else line)
        expected.append([float(w) for w in words] + [float(ew), float(fw) / 60])
    want = np.array(expected)
    m = moves(read("\n".join(lines)))
    # drop programmed moves that do not move anything, as the reader does
    prev = np.vstack([[0, 0, 0, 0], want[:-1, :4]])
    real = np.any(np.abs(want[:, :4] - prev) > 1e-9, axis=1)
    np.testing.assert_array_equal(m["end"], want[real, :3])
    np.testing.assert_array_equal(m["e_end"], want[real, 3])
    np.testing.assert_array_equal(m["feedrate"], want[real, 4])
    np.testing.assert_array_equal(m["line"], np.flatnonzero(real) + 1)


piece = st.sampled_from(
    [
        "G1",
        "g0",
        "M104",
        "X",
        "y",
        "E",
        "F",
        "S",
        "N",
        " ",
        " ",
        "\t",
        "1",
        "-2",
        "+3",
        ".5",
        "5.",
        "0.25",
        "1.2.3",
        "--1",
        "-",
        ".",
        "#",
        "(c)",
        "*7",
        "12345678901234567",
        "007",
        "-.0",
        "T0",
    ]
)


@given(st.lists(st.lists(piece, max_size=8).map("".join), min_size=1, max_size=12))
def test_fast_tokens_equal_exact_parser(lines):
    code = "\n".join(lines) + "\n"
    tok = tokenize(code.encode())
    slow = set(tok.slow.tolist())
    for index, text in enumerate(lines):
        mine = tok.line == index
        got = [(chr(a), b) for a, b in zip(tok.letter[mine].tolist(), tok.value[mine].tolist())]
        if index in slow:
            assert not got
            continue
        words = parse_line(
            text, index + 1, "t"
        ).words  # the fast path only takes lines the exact parser reads cleanly
        assert got == [(w.letter, w.value) for w in words]
        assert all(w.value is not None for w in words)
