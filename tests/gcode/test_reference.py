"""Random programs mixing modes, offsets and units: the vectorised reader against a plain interpreter."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from .helpers import moves, read

num = st.integers(-2000, 2000).map(lambda k: k / 8)  # exact in binary: sums stay exact
axes = st.lists(st.sampled_from("XYZE"), min_size=1, max_size=4, unique=True)
four = st.lists(num, min_size=4, max_size=4)
statement = st.one_of(
    st.tuples(
        st.sampled_from(["G0", "G1"]), axes, four, st.one_of(st.none(), st.integers(1, 9000))
    ),
    st.tuples(st.just("G92"), axes, four, st.none()),
    st.sampled_from(
        ["G90", "G91", "M82", "M83", "G20", "G21", "G92", "G28", "M106 S9", ";LAYER_CHANGE"]
    ),
)


def render(stmts) -> str:
    out = []
    for s in stmts:
        if isinstance(s, str):
            out.append(s)
            continue
        cmd, ax, vals, f = s
        words = [f"{a}{v:g}" for a, v in zip(ax, vals)]
        if f is not None:
            words.append(f"F{f}")
        out.append(" ".join([cmd, *words]))
    return "\n".join(out) + "\n"


def reference(stmts, home):
    """One statement at a time: each real move as (x, y, z, e) before, after, feed mm/s, line."""
    pos = np.array([*home, 0.0])
    off = np.zeros(4)
    rel = rel_e = False
    scale, feed = 1.0, 25.0
    out = []
    for line, s in enumerate(stmts, start=1):
        if isinstance(s, str):
            if s in ("G90", "G91"):
                rel = s == "G91"
            elif s in ("M82", "M83"):
                rel_e = s == "M83"
            elif s in ("G20", "G21"):
                scale = 25.4 if s == "G20" else 1.0
            elif s == "G92":
                off = pos.copy()
            elif s == "G28":
                pos[:3] = home
                off[:3] = 0.0
            continue
        cmd, ax, vals, f = s
        new = pos.copy()
        for a, v in zip(ax, vals):
            k = "XYZE".index(a)
            v *= scale
            if cmd == "G92":
                off[k] = pos[k] - v
            elif rel or (k == 3 and rel_e):
                new[k] = pos[k] + v
            else:
                new[k] = v + off[k]
        if f is not None:
            feed = f * scale / 60
        if cmd != "G92" and np.any(np.abs(new - pos) > 1e-9):
            out.append([*pos, *new, feed, line])
        pos = new
    return np.array(out).reshape(-1, 10)


@settings(max_examples=150)
@given(st.lists(statement, max_size=60), st.integers(1, 25))
def test_reader_matches_plain_interpreter(stmts, block_lines):
    home = (1.0, -2.0, 30.0)
    want = reference(stmts, home)
    m = moves(read(render(stmts), home_position=home, block_lines=block_lines))
    got = np.column_stack(
        [m["start"], m["e_start"], m["end"], m["e_end"], m["feedrate"], m["line"]]
    )
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
