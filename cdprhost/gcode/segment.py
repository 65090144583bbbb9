"""Rows of one run (fixed modes) -> absolute linear moves, kinds and layers, vectorised."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.gcode import arcs
from cdprhost.gcode.annotations import LayerStyle
from cdprhost.gcode.items import CHUNK_FIELDS, LayerChange, MoveChunk, MoveKind
from cdprhost.gcode.positions import forward_fill, resolve_axis
from cdprhost.gcode.state import ModalState

# Rows of Rows.values.
X, Y, Z, E, F, I, J, R = range(8)  # noqa: E741 - G-code's own axis letters
COLUMNS = "XYZEFIJR"
G92 = 92
EPS_MM = 1e-9
NO_MOTION = 255


@dataclass(frozen=True, slots=True)
class Rows:
    """Motion rows of a block, in order: ``cmd`` 0-3 (G0-G3) or 92; ``values`` (8, m), NaN = absent."""

    line: np.ndarray
    cmd: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.line.shape[0])

    def part(self, a: int, b: int) -> Rows:
        return Rows(self.line[a:b], self.cmd[a:b], self.values[:, a:b])


@dataclass(frozen=True, slots=True)
class SegmentResult:
    """Moves of a run; height-detected layer starts; the first arc error (line, reason)."""

    moves: MoveChunk
    layer_starts: list[LayerChange]
    error: tuple[int, str] | None


def compute(rows: Rows, st: ModalState, tolerance: float, layer_lines: np.ndarray) -> SegmentResult:
    """Moves for ``rows`` from state ``st`` (updated to the state after the last row).

    ``layer_lines``: lines of the layer annotations inside this run (annotated files).
    """
    vals = rows.values if st.scale == 1.0 else rows.values * st.scale
    m = vals.shape[1]
    set_row = rows.cmd == G92
    any_set = bool(set_row.any())
    track = np.empty((m + 1, 4))
    track[0] = st.pos
    off = st.off.copy()
    for a in range(4):
        absolute = st.abs_xyz if a < 3 else st.abs_e
        track[1:, a], off[a] = resolve_axis(
            vals[a], set_row if any_set else None, st.pos[a], st.off[a], absolute
        )
    feed = forward_fill(vals[F] / 60.0, st.feed)
    st.pos = track[-1].copy()
    st.off = off
    st.feed = float(feed[-1])
    if st.speed_factor != 1.0:
        feed = feed * st.speed_factor
    factor = st.e_factor
    if factor != 1.0 or st.e_machine != track[0, 3]:
        track[:, 3] = st.e_machine + (track[:, 3] - track[0, 3]) * factor
    st.e_machine = float(track[-1, 3])

    # G92 rows stay in: they do not move, so they are dropped with the other non-moves.
    before, after = track[:-1], track[1:]
    cmd, line = rows.cmd, rows.line
    is_arc = cmd == 2
    is_arc |= cmd == 3
    row_layer, layer_starts = _row_layers(before, after, is_arc, line, st, layer_lines)
    error = None
    if is_arc.any():
        if st.plane != 17:
            k = int(np.flatnonzero(is_arc)[0])
            error = (int(line[k]), f"unsupported plane G{st.plane} for arcs (only G17, XY)")
        else:
            counts, before, after, error = _expand_arcs(
                before, after, vals, cmd, line, is_arc, tolerance
            )
            feed, line, cmd, row_layer = (
                np.repeat(a, counts) for a in (feed, line, cmd, row_layer)
            )

    kind = classify(before, after)
    keep = np.flatnonzero(kind != NO_MOTION)
    moves = MoveChunk(
        start=before[keep, :3],
        end=after[keep, :3],
        e_start=before[keep, 3],
        e_end=after[keep, 3],
        feedrate=feed[keep],
        line=line[keep],
        layer=row_layer[keep],
        kind=kind[keep],
        rapid=cmd[keep] == 0,
    )
    for name in CHUNK_FIELDS:
        getattr(moves, name).flags.writeable = False
    return SegmentResult(moves, layer_starts, error)


def _kind_table() -> np.ndarray:
    """`MoveKind` by code = moved_xy + 2 moved_z + 4 e_forward + 8 e_backward."""
    table = np.full(16, NO_MOTION, dtype=np.uint8)
    for code in range(16):
        xy, z, fwd, back = code & 1, code & 2, code & 4, code & 8
        if fwd and back:
            continue
        moved = xy or z
        if fwd:
            table[code] = MoveKind.EXTRUDE if moved else MoveKind.UNRETRACT
        elif back:
            table[code] = MoveKind.WIPE if moved else MoveKind.RETRACT
        elif moved:
            table[code] = MoveKind.TRAVEL if xy else MoveKind.Z_ONLY
    return table


_KIND = _kind_table()


def classify(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """`MoveKind` per move from (n, 4) X, Y, Z, E; ``NO_MOTION`` (255) for moves that do nothing."""
    d = end - start
    moving = (np.abs(d) > EPS_MM).view(np.uint8)
    code = moving[:, 0] | moving[:, 1]
    code |= moving[:, 2] << 1
    code |= ((d[:, 3] > EPS_MM).view(np.uint8) << 2) | ((d[:, 3] < -EPS_MM).view(np.uint8) << 3)
    return _KIND[code]


def _row_layers(
    before: np.ndarray,
    after: np.ndarray,
    is_arc: np.ndarray,
    line: np.ndarray,
    st: ModalState,
    layer_lines: np.ndarray,
) -> tuple[np.ndarray, list[LayerChange]]:
    """Layer per moving row; for height-detected layers also the new-layer records."""
    if st.layer_style not in (None, LayerStyle.HEIGHT):
        if layer_lines.size == 0:
            return np.full(line.size, st.layer, dtype=np.int32), []
        return (st.layer + np.searchsorted(layer_lines, line)).astype(np.int32), []
    d = after - before
    moved = is_arc | (np.abs(d[:, :3]) > EPS_MM).any(axis=1)
    extruding = moved & (d[:, 3] > EPS_MM)
    if not extruding.any():
        return np.full(line.size, st.layer, dtype=np.int32), []
    st.layer_style = LayerStyle.HEIGHT  # extrusion before any layer annotation: detect by height
    z = after[extruding, 2]
    top = np.maximum.accumulate(np.concatenate([[st.z_top], z]))
    new = z > top[:-1] + 1e-6
    st.z_top = float(top[-1])
    flags = np.zeros(line.size, dtype=np.int32)
    where = np.flatnonzero(extruding)[new]
    flags[where] = 1
    layer = st.layer + np.cumsum(flags, dtype=np.int32)
    starts = [LayerChange(int(line[k]), int(layer[k]), float(after[k, 2])) for k in where.tolist()]
    return layer, starts


def _expand_arcs(
    before: np.ndarray,
    after: np.ndarray,
    vals: np.ndarray,
    cmd: np.ndarray,
    line: np.ndarray,
    is_arc: np.ndarray,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, str] | None]:
    """Replace each arc row by its chords; (counts per row, before, after, first error)."""
    idx = np.flatnonzero(is_arc)
    start, end = before[idx], after[idx]
    geo = arcs.geometry(
        start[:, :2], end[:, :2], vals[[I, J]][:, idx].T, vals[R, idx], cmd[idx] == 2
    )
    error = None
    if geo.bad:
        k, reason = geo.bad[0]
        error = (int(line[idx[k]]), reason)
    n_seg = arcs.within_budget(arcs.segment_counts(geo, tolerance), lengths=arcs.arc_lengths(geo))
    counts = np.ones(cmd.size, dtype=np.int64)
    counts[idx] = n_seg
    ends = np.repeat(after, counts, axis=0)
    first = np.cumsum(counts) - counts
    within = np.arange(int(n_seg.sum())) - np.repeat(np.cumsum(n_seg) - n_seg, n_seg)
    ends[np.repeat(first[idx], n_seg) + within] = arcs.chord_ends(geo, n_seg, start, end)
    starts = np.vstack([before[:1], ends[:-1]])
    return counts, starts, ends, error
