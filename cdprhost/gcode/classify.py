"""Tokens of a block -> motion rows (vectorised) and the other command lines.

Also finds the static problems of motion lines (unsupported or repeated
parameters, missing numbers, F <= 0, arcs without I/J or R); the reader reports the
earliest one, with its column.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.gcode.segment import COLUMNS, G92, Rows
from cdprhost.gcode.tokenize import Tokens

_G = ord("G")
_COLUMN = np.full(256, 8, dtype=np.int64)
for _k, _c in enumerate(COLUMNS):
    _COLUMN[ord(_c)] = _k
# Allowed parameter columns per motion kind: 0 = G0/G1, 1 = G2/G3, 2 = G92 (column 8: not a motion letter).
_ALLOWED = np.zeros((3, 9), dtype=bool)
_ALLOWED[0, :5] = True
_ALLOWED[1, :8] = True
_ALLOWED[2, :4] = True
_ALLOWED_FLAT = _ALLOWED.ravel()


@dataclass(frozen=True, slots=True)
class Other:
    """A non-motion line: ``word`` like ``M104``; ``params`` letter -> value (NaN: bare letter)."""

    index: int
    word: str
    params: dict[str, float]
    text: str | None


@dataclass(frozen=True, slots=True)
class Problem:
    """A static error at block line ``index``: the ``occurrence``-th word with ``letter``."""

    index: int
    letter: str | None
    occurrence: int
    reason: str


@dataclass(frozen=True, slots=True)
class Classified:
    """Motion rows, other command lines (in order) and the earliest static problem."""

    rows: Rows
    others: list[Other]
    problem: Problem | None


def command_word(letter: int, value: float) -> str:
    """``G1``, ``M862.3``: a command as text."""
    if value == int(value):
        return f"{chr(letter)}{int(value)}"
    return f"{chr(letter)}{value:g}"


def classify(tok: Tokens, first_line: int, texts: dict[int, str]) -> Classified:
    """Split ``tok`` into motion rows and other lines (``texts``: free text of slow lines)."""
    tl, let, val = tok.line, tok.letter, tok.value
    if tl.size == 0:
        return Classified(
            Rows(np.empty(0, np.int64), np.empty(0, np.uint8), np.empty((8, 0))), [], None
        )
    first = np.empty(tl.size, dtype=bool)
    first[0] = True
    np.not_equal(tl[1:], tl[:-1], out=first[1:])
    head = np.flatnonzero(first)
    group = np.cumsum(first) - 1
    count = np.diff(np.append(head, tl.size))
    cmd_val = val[head]
    cmd_let = let[head]
    is_g = (cmd_let == _G) & (cmd_val == np.floor(cmd_val))
    motion = is_g & (((cmd_val >= 0) & (cmd_val <= 3)) | ((cmd_val == G92) & (count > 1)))
    kind = np.where(cmd_val >= 2, 1, 0)
    kind[cmd_val == G92] = 2

    row_of_group = np.cumsum(motion) - 1
    param = np.flatnonzero(~first & motion[group])  # parameter tokens of motion lines
    pg = group[param]
    row = row_of_group[pg]
    col = _COLUMN[let[param]]
    pval = val[param]
    m = int(np.count_nonzero(motion))
    problems: list[Problem] = []
    ok = _ALLOWED_FLAT[kind[pg] * 9 + col]
    if not ok.all():
        problems.append(_problem(tok, param[~ok], head, group, "unsupported parameter {w} in {c}"))
        row, col, pval, param = row[ok], col[ok], pval[ok], param[ok]
    number = ~np.isnan(pval)
    if not number.all():
        problems.append(
            _problem(tok, param[~number], head, group, "missing number after {w} in {c}")
        )
    nonpos_f = (col == 4) & ~(pval > 0) & number
    if nonpos_f.any():
        problems.append(
            _problem(tok, param[nonpos_f], head, group, "feedrate must be positive: {w} in {c}")
        )
    values = np.full((8, m), np.nan)
    values[col, row] = pval
    if np.count_nonzero(~np.isnan(values)) != np.count_nonzero(number):  # a cell written twice
        key = row * 8 + col
        dup = np.bincount(key, minlength=m * 8)[key] > 1
        problems.append(
            _problem(tok, param[dup], head, group, "repeated parameter {w} in {c}", second=True)
        )

    rows = Rows(tl[head[motion]] + first_line, cmd_val[motion].astype(np.uint8), values)
    arc_problem = _arc_problem(rows, tl[head[motion]], kind[motion])
    if arc_problem is not None:
        problems.append(arc_problem)
    others = [
        Other(
            int(tl[h]),
            command_word(int(let[h]), float(val[h])),
            _params(let, val, h, c),
            texts.get(int(tl[h])),
        )
        for h, c in zip(head[~motion].tolist(), count[~motion].tolist())
    ]
    problem = min(problems, key=lambda p: p.index) if problems else None
    return Classified(rows, others, problem)


def _params(let: np.ndarray, val: np.ndarray, h: int, c: int) -> dict[str, float]:
    return {chr(a): b for a, b in zip(let[h + 1 : h + c].tolist(), val[h + 1 : h + c].tolist())}


def _problem(tok: Tokens, tokens, head, group, template: str, second: bool = False) -> Problem:
    """The earliest of the flagged tokens as a `Problem` (``second``: its repeat on that line)."""
    t = int(tokens[0])
    if second:
        same = tokens[(tok.line[tokens] == tok.line[t]) & (tok.letter[tokens] == tok.letter[t])]
        t = int(same[1])
    h = int(head[group[t]])
    letter = chr(int(tok.letter[t]))
    occurrence = int(np.count_nonzero(tok.letter[h:t] == tok.letter[t]))
    word = letter if np.isnan(tok.value[t]) else f"{letter}{_fmt(tok.value[t])}"
    cmd = command_word(int(tok.letter[h]), float(tok.value[h]))
    return Problem(int(tok.line[t]), letter, occurrence, template.format(w=f"'{word}'", c=cmd))


def _fmt(v: float) -> str:
    return f"{v:g}"


def _arc_problem(rows: Rows, index: np.ndarray, kind: np.ndarray) -> Problem | None:
    """Arcs need exactly one of I/J and R; ``index``: block line of each row."""
    arc = kind == 1
    if not arc.any():
        return None
    v = rows.values
    has_ij = ~np.isnan(v[5]) | ~np.isnan(v[6])
    has_r = ~np.isnan(v[7])
    both = arc & has_ij & has_r
    neither = arc & ~has_ij & ~has_r
    cands = []
    if both.any():
        k = int(np.flatnonzero(both)[0])
        cands.append(Problem(int(index[k]), "R", 0, f"G{rows.cmd[k]} has both I/J and R"))
    if neither.any():
        k = int(np.flatnonzero(neither)[0])
        cands.append(
            Problem(
                int(index[k]), "G", 0, f"G{rows.cmd[k]} needs I/J (centre offset) or R (radius)"
            )
        )
    return min(cands, key=lambda p: p.index) if cands else None
