"""Tokens of a block -> motion rows (vectorised) and the other command lines.

A motion row is a G0-G3 or G92 line, or a line that continues the last motion
command (``X10 Y5`` with no G word; a bare ``F1800`` sets the feedrate). Also finds
the static problems of motion lines (repeated parameters, missing numbers, F <= 0,
arcs without I/J or R); the reader reports the earliest one, with its column.
Parameters a printer ignores on a motion line (``S0`` on ``G0``, an ``A`` axis) are
listed, not refused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.gcode.items import IgnoredParameters
from cdprhost.gcode.segment import COLUMNS, G92, Rows
from cdprhost.gcode.tokenize import Tokens

_G = ord("G")
_F_COLUMN = COLUMNS.index("F")
_P = ord("P")
_CONTINUES = np.zeros(
    256, dtype=bool
)  # a line starting with one of these continues the motion mode
_CONTINUES[[ord(c) for c in COLUMNS]] = True
CONTINUE = 255  # Rows.cmd of a continuation line before its mode is known
_COLUMN = np.full(256, 8, dtype=np.int64)
for _k, _c in enumerate(COLUMNS):
    _COLUMN[ord(_c)] = _k
# Allowed parameter columns per motion kind: 0 = G0/G1, 1 = G2/G3 and continuation
# lines, 2 = G92 (column 8: not a motion letter).
_ALLOWED = np.zeros((3, 9), dtype=bool)
_ALLOWED[0, :5] = True
_ALLOWED[1, :8] = True
_ALLOWED[2, :4] = True
_ALLOWED_FLAT = _ALLOWED.ravel()


@dataclass(frozen=True, slots=True)
class Other:
    """A non-motion line: ``word`` like ``M104``; ``params`` letter -> value (NaN: bare letter).

    Extended (Klipper) commands carry ``extended``: their ``KEY=value`` parameters.
    """

    index: int
    word: str
    params: dict[str, float]
    text: str | None
    extended: dict[str, str] | None = None


@dataclass(frozen=True, slots=True)
class Problem:
    """A static error at block line ``index``: the ``occurrence``-th word with ``letter``."""

    index: int
    letter: str | None
    occurrence: int
    reason: str


@dataclass(frozen=True, slots=True)
class Classified:
    """Motion rows, other command lines (in order), ignored parameters (block line index,
    record with line 0) and the earliest static problem. ``motion_mode``: the G0-G3
    mode after the block."""

    rows: Rows
    others: list[Other]
    problem: Problem | None
    ignored: list[tuple[int, IgnoredParameters]]
    motion_mode: int | None


def command_word(letter: int, value: float) -> str:
    """``G1``, ``M862.3``: a command as text."""
    if value == int(value):
        return f"{chr(letter)}{int(value)}"
    return f"{chr(letter)}{value:g}"


def classify(
    tok: Tokens, first_line: int, texts: dict[int, str], motion_mode: int | None = None
) -> Classified:
    """Split ``tok`` into motion rows and other lines (``texts``: free text of slow lines).

    ``motion_mode``: the G0-G3 mode before the block (None: none yet), which lines
    without a G word continue.
    """
    tl, let, val = tok.line, tok.letter, tok.value
    if tl.size == 0:
        return Classified(
            Rows(np.empty(0, np.int64), np.empty(0, np.uint8), np.empty((8, 0))),
            [],
            None,
            [],
            motion_mode,
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
    cont = _CONTINUES[cmd_let]
    motion = (is_g & (((cmd_val >= 0) & (cmd_val <= 3)) | ((cmd_val == G92) & (count > 1)))) | cont
    kind = np.where(cmd_val >= 2, 1, 0)
    kind[cmd_val == G92] = 2
    kind[cont] = 1

    row_of_group = np.cumsum(motion) - 1
    # parameter tokens of motion lines (a continuation line's first word is one too)
    param = np.flatnonzero(motion[group] & (~first | cont[group]))
    pg = group[param]
    row = row_of_group[pg]
    col = _COLUMN[let[param]]
    pval = val[param]
    m = int(np.count_nonzero(motion))
    problems: list[Problem] = []
    ignored: list[tuple[int, IgnoredParameters]] = []
    ok = _ALLOWED_FLAT[kind[pg] * 9 + col]
    if not ok.all():
        turns = ~ok & (let[param] == _P) & (kind[pg] == 1) & ~cont[pg]
        if turns.any():
            problems.append(
                _problem(tok, param[turns], head, group, "{w} (full turns) is not supported in {c}")
            )
        ignored = _ignored(tok, param[~ok & ~turns], head, group)
        row, col, pval, param = row[ok], col[ok], pval[ok], param[ok]
    number = ~np.isnan(pval)
    if not number.all():
        problems.append(
            _problem(tok, param[~number], head, group, "missing number after {w} in {c}")
        )
    nonpos_f = (col == _F_COLUMN) & ~(pval > 0) & number
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

    index = tl[head[motion]]
    cmd = np.where(cont[motion], CONTINUE, cmd_val[motion]).astype(np.uint8)
    cmd, motion_mode, orphan = _resolve_continuations(cmd, values, motion_mode)
    if orphan is not None:
        k = int(head[motion][orphan])
        word = command_word(int(let[k]), float(val[k]))
        problems.append(
            Problem(
                int(tl[k]),
                chr(int(let[k])),
                0,
                f"'{word}' continues no motion command (no G0, G1, G2 or G3 before it)",
            )
        )
    stray = cont[motion] & (cmd <= 1) & ~np.isnan(values[5:8]).all(axis=0)
    if stray.any():  # I, J or R on a line continuing G0/G1
        for r in np.flatnonzero(stray).tolist():
            letters = " ".join(
                f"{c}{_fmt(values[5 + k, r])}"
                for k, c in enumerate("IJR")
                if not np.isnan(values[5 + k, r])
            )
            ignored.append((int(index[r]), IgnoredParameters(0, f"G{cmd[r]}", letters)))
        values[5:8, stray] = np.nan
        ignored.sort(key=lambda e: e[0])
    rows = Rows(index + first_line, cmd, values)
    arc_problem = _arc_problem(rows, index, (cmd == 2) | (cmd == 3))
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
    return Classified(rows, others, problem, ignored, motion_mode)


def _resolve_continuations(
    cmd: np.ndarray, values: np.ndarray, mode: int | None
) -> tuple[np.ndarray, int | None, int | None]:
    """Continuation rows take the last G0-G3 before them (a bare F row: G1).

    Returns the commands, the mode after the rows, and the first row that continues
    nothing (or None).
    """
    is_mode = cmd <= 3
    cont = cmd == CONTINUE
    mode_after = int(cmd[np.flatnonzero(is_mode)[-1]]) if is_mode.any() else mode
    if not cont.any():
        return cmd, mode_after, None
    idx = np.where(is_mode, np.arange(cmd.size), -1)
    np.maximum.accumulate(idx, out=idx)
    before = np.where(idx >= 0, cmd[np.maximum(idx, 0)], 255 if mode is None else mode)
    feed_only = np.isnan(np.delete(values, _F_COLUMN, axis=0)).all(axis=0)
    out = np.where(cont, np.where(feed_only, 1, before), cmd).astype(np.uint8)
    orphan = np.flatnonzero(out == 255)
    return out, mode_after, (int(orphan[0]) if orphan.size else None)


def _ignored(
    tok: Tokens, tokens: np.ndarray, head: np.ndarray, group: np.ndarray
) -> list[tuple[int, IgnoredParameters]]:
    """One record per line with ignored parameters: (block line index, record with line 0)."""
    out: list[tuple[int, IgnoredParameters]] = []
    lines = tok.line[tokens]
    for ln in np.unique(lines).tolist():
        on_line = tokens[lines == ln]
        h = int(head[group[int(on_line[0])]])
        word = command_word(int(tok.letter[h]), float(tok.value[h]))
        letters = "".join(
            f"{chr(int(tok.letter[t]))}{'' if np.isnan(tok.value[t]) else _fmt(tok.value[t])} "
            for t in on_line.tolist()
        ).strip()
        out.append((int(ln), IgnoredParameters(0, word, letters)))
    return out


def _params(let: np.ndarray, val: np.ndarray, h: int, c: int) -> dict[str, float]:
    return {chr(a): b for a, b in zip(let[h + 1 : h + c].tolist(), val[h + 1 : h + c].tolist())}


def _problem(
    tok: Tokens,
    tokens: np.ndarray,
    head: np.ndarray,
    group: np.ndarray,
    template: str,
    second: bool = False,
) -> Problem:
    """The earliest of the flagged tokens as a `Problem` (``second``: its repeat on that line)."""
    t = int(tokens[0])
    if second:
        same = tokens[(tok.line[tokens] == tok.line[t]) & (tok.letter[tokens] == tok.letter[t])]
        t = int(same[1])
    h = int(head[group[t]])
    letter = chr(int(tok.letter[t]))
    occurrence = int(np.count_nonzero(tok.letter[h:t] == tok.letter[t]))
    word = letter if np.isnan(tok.value[t]) else f"{letter}{_fmt(tok.value[t])}"
    if _CONTINUES[int(tok.letter[h])]:
        cmd = "a line continuing the motion command"
    else:
        cmd = command_word(int(tok.letter[h]), float(tok.value[h]))
    return Problem(int(tok.line[t]), letter, occurrence, template.format(w=f"'{word}'", c=cmd))


def _fmt(v: float) -> str:
    return f"{v:g}"


def _arc_problem(rows: Rows, index: np.ndarray, arc: np.ndarray) -> Problem | None:
    """Arcs need exactly one of I/J and R; ``index``: block line of each row."""
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
