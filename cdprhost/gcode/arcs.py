"""G2/G3 arcs in the XY plane, segmented into chords within a deviation tolerance.

Centre from I/J (offsets from the start) or from R (negative R: the long way round).
Z and E are interpolated along the arc (helices). A start equal to the end with I/J
is a full circle. If the end is not exactly on the circle the radius is blended
linearly from start to end (as LinuxCNC does), within ``radius_tolerance``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FULL_CIRCLE_MM = 1e-6  # start and end closer than this (XY): full circle with I/J
#: chords of all arcs resolved at once (one run of a block): bounds memory whatever the
#: radii; real files stay far below (a boat's 3,837 arcs make about 26,000 chords)
CHORD_BUDGET = 1 << 18
#: chords of one arc at most (arcs up to 2 m long keep 0.001 mm with fewer)
MAX_CHORDS_PER_ARC = 4096
#: arcs longer than this (mm) fit no printer: at most ``LONG_ARC_CHORDS`` chords
LONG_ARC_MM = 2000.0
LONG_ARC_CHORDS = 16


@dataclass(frozen=True, slots=True)
class ArcGeometry:
    """Per arc: centre (n, 2), start/end radius, start angle, signed sweep (rad); ``bad`` reasons."""

    centre: np.ndarray
    r0: np.ndarray
    r1: np.ndarray
    a0: np.ndarray
    sweep: np.ndarray
    bad: list[tuple[int, str]]


def radius_tolerance(r: np.ndarray) -> np.ndarray:
    """How far the end may sit off the circle before the arc is refused (mm)."""
    return 0.01 + 1e-3 * np.abs(r)


def geometry(
    start: np.ndarray, end: np.ndarray, ij: np.ndarray, r: np.ndarray, clockwise: np.ndarray
) -> ArcGeometry:
    """``start``/``end`` (n, 2) XY; ``ij`` (n, 2) with NaN where absent; ``r`` (n,) NaN if absent."""
    bad: list[tuple[int, str]] = []
    chord = end - start
    d = np.hypot(chord[:, 0], chord[:, 1])
    use_r = ~np.isnan(r)
    centre = start + np.nan_to_num(ij)
    if use_r.any():
        rr = np.abs(r[use_r])
        dd = d[use_r]
        h2 = rr**2 - (dd / 2) ** 2
        too_small = h2 < 0
        refuse = too_small & (dd / 2 - rr > radius_tolerance(rr))
        h = np.sqrt(np.maximum(h2, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            u = chord[use_r] / dd[:, None]
        right = np.stack([u[:, 1], -u[:, 0]], axis=1)
        # G2 with R > 0 (short way): centre right of the chord; flip for G3 and for R < 0.
        side = np.where(clockwise[use_r], 1.0, -1.0) * np.sign(r[use_r])
        centre[use_r] = (start[use_r] + end[use_r]) / 2 + (side * h)[:, None] * right
        idx = np.flatnonzero(use_r)
        for k in idx[dd == 0].tolist():
            bad.append((k, "R arc with start equal to end (use I/J for a full circle)"))
        for k in idx[refuse & (dd > 0)].tolist():
            bad.append((k, f"arc radius R{abs(r[k]):g} too small for a chord of {d[k]:.4f} mm"))
    v0 = start - centre
    v1 = end - centre
    r0 = np.hypot(v0[:, 0], v0[:, 1])
    r1 = np.hypot(v1[:, 0], v1[:, 1])
    for k in np.flatnonzero(r0 == 0).tolist():
        bad.append((k, "arc with zero radius"))
    mismatch = np.abs(r1 - r0) > radius_tolerance(np.maximum(r0, r1))
    for k in np.flatnonzero(mismatch & ~use_r & (r0 > 0)).tolist():
        bad.append(
            (k, f"arc end is not on the circle: radius {r0[k]:.4f} at start, {r1[k]:.4f} at end")
        )
    a0 = np.arctan2(v0[:, 1], v0[:, 0])
    a1 = np.arctan2(v1[:, 1], v1[:, 0])
    ccw = np.mod(a1 - a0, 2 * np.pi)
    full = (d < FULL_CIRCLE_MM) & ~use_r
    ccw = np.where(full | (ccw == 0), 2 * np.pi, ccw)
    cw = np.where(full | (ccw == 2 * np.pi), 2 * np.pi, 2 * np.pi - ccw)
    sweep = np.where(clockwise, -cw, ccw)
    bad.sort()
    return ArcGeometry(centre, r0, r1, a0, sweep, bad)


def segment_counts(geo: ArcGeometry, tolerance: float) -> np.ndarray:
    """Chords per arc so that each chord's sagitta is within ``tolerance`` (at least 1)."""
    r = np.maximum(geo.r0, geo.r1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_half = np.clip(1.0 - tolerance / r, -1.0, 1.0)
        step = np.minimum(2.0 * np.arccos(cos_half), np.pi / 2)
        n = np.ceil(np.abs(geo.sweep) / step)
    return np.maximum(np.nan_to_num(n, nan=1.0), 1).astype(np.int64)


def arc_lengths(geo: ArcGeometry) -> np.ndarray:
    """Length of each arc in the XY plane (mm)."""
    return np.abs(geo.sweep) * np.maximum(geo.r0, geo.r1)


def within_budget(
    counts: np.ndarray, budget: int = CHORD_BUDGET, lengths: np.ndarray | None = None
) -> np.ndarray:
    """``counts`` capped so that no arc has more than ``MAX_CHORDS_PER_ARC`` chords and all
    together no more than ``budget``: the largest counts are lowered to a common cap.

    Only absurd arcs (radii of metres, or a run of thousands of large circles) are
    affected; their chords then deviate more than the tolerance, and preflight
    refuses them anyway for leaving the build volume.
    """
    counts = np.minimum(counts, MAX_CHORDS_PER_ARC)
    if lengths is not None:
        counts = np.where(lengths > LONG_ARC_MM, np.minimum(counts, LONG_ARC_CHORDS), counts)
    if int(counts.sum()) <= budget:
        return counts
    ordered = np.sort(counts)
    n = ordered.size
    prefix = np.concatenate([[0], np.cumsum(ordered)[:-1]])  # sum of the k smallest
    cap = (budget - prefix) // (n - np.arange(n))  # the rest capped: largest cap that fits
    fits = np.concatenate([[True], ordered[:-1] <= cap[1:]])
    k = int(np.flatnonzero(fits & (cap >= 0))[-1]) if (fits & (cap >= 0)).any() else 0
    return np.maximum(np.minimum(counts, max(int(cap[k]), 1)), 1)


def chord_ends(
    geo: ArcGeometry, counts: np.ndarray, start: np.ndarray, end: np.ndarray
) -> np.ndarray:
    """End point (x, y, z, e) of every chord, arcs one after another (sum(counts), 4).

    ``start``/``end`` are (n, 4) X, Y, Z, E of each arc; the last chord ends exactly at ``end``.
    """
    total = int(counts.sum())
    arc = np.repeat(np.arange(counts.size), counts)
    first = np.cumsum(counts) - counts
    t = (np.arange(total) - first[arc] + 1) / counts[arc]
    ang = geo.a0[arc] + geo.sweep[arc] * t
    rad = geo.r0[arc] + (geo.r1 - geo.r0)[arc] * t
    out = np.empty((total, 4))
    out[:, 0] = geo.centre[arc, 0] + rad * np.cos(ang)
    out[:, 1] = geo.centre[arc, 1] + rad * np.sin(ang)
    out[:, 2:] = start[arc, 2:] + (end - start)[arc, 2:] * t[:, None]
    out[np.cumsum(counts) - 1] = end
    return out
