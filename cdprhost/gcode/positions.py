"""Vectorised modal arithmetic: programmed values of one axis -> absolute positions, per row.

A *row* is one G0/G1/G2/G3 or G92 line. Within a run of rows the distance mode and
units are fixed, so absolute positions follow from a forward fill (absolute mode) or
a cumulative sum (relative mode); G92 rows shift the offset without moving.
"""

from __future__ import annotations

import numpy as np


def forward_fill(values: np.ndarray, initial: float) -> np.ndarray:
    """``values`` with each NaN replaced by the last number before it (``initial`` at the start)."""
    given = ~np.isnan(values)
    idx = np.where(given, np.arange(1, values.size + 1), 0)
    np.maximum.accumulate(idx, out=idx)
    return np.concatenate(([initial], values))[idx]


def resolve_axis(
    values: np.ndarray,
    set_row: np.ndarray | None,
    pos0: float,
    off0: float,
    absolute: bool,
) -> tuple[np.ndarray, float]:
    """Absolute position after each row and the offset after the last one.

    ``values`` (m,) programmed numbers in mm, NaN where the axis is not written;
    ``set_row`` marks G92 rows (None: there are none). Position = programmed +
    offset; ``G92 v`` makes the offset ``position - v``.
    """
    given = ~np.isnan(values)
    is_set = None if set_row is None else given & set_row
    if is_set is not None and not is_set.any():
        is_set = None
    if absolute:
        q0 = pos0 - off0
        q = forward_fill(values, q0)
        if is_set is None:
            return q + off0, off0
        q_before = np.concatenate(([q0], q[:-1]))
        off = off0 + np.cumsum(np.where(is_set, q_before - values, 0.0))
        return q + off, float(off[-1])
    step = np.where(given if is_set is None else given & ~is_set, values, 0.0)
    pos = pos0 + np.cumsum(step)
    if is_set is None:
        return pos, off0
    last = int(np.flatnonzero(is_set)[-1])
    return pos, float(pos[last] - values[last])
