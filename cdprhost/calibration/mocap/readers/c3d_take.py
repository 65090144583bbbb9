"""C3D binary takes through the ``c3d`` package: read into / write from :class:`Take`.

Marker names come from ``POINT:LABELS`` (and ``LABELS2``... for large files), the
unit from ``POINT:UNITS`` (mm, cm or m): one string for every point, or (Optotrak and
some other exporters) an array with one unit per point. A negative residual marks a gap.
A file without 3D points (``POINT:USED`` = 0: only rotations or analog channels) is
refused with a clear message.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from cdprhost.calibration.mocap.readers.take import Take, unit_scale
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import atomic_open

FORMAT = "c3d"


def looks_like_c3d(head: bytes) -> bool:
    """C3D header: byte 0 points at the parameter block, byte 1 is the key 0x50."""
    return len(head) >= 2 and head[1] == 0x50 and head[0] >= 1


def _labels(reader: Any) -> list[str]:
    labels: list[str] = []
    for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 10)]:
        param = reader.get(f"POINT:{key}")
        if param is None:
            break
        labels.extend(str(s).strip() for s in param.string_array)
    return labels


def _point_units(reader: Any, n_points: int, src: str, notes: list[str]) -> np.ndarray:
    """Millimetres per stored unit for each point, from ``POINT:UNITS`` (a string, or an
    array of one string per point)."""
    param = reader.get("POINT:UNITS")
    if param is None:
        notes.append("no POINT:UNITS; assumed mm")
        return np.ones(n_points)
    dims = list(getattr(param, "dimensions", []) or [])
    if len(dims) >= 2 and dims[1] > 1:
        units = [str(u).strip() for u in np.ravel(param.string_array)]
    else:
        units = [param.string_value.strip()]
    if len(units) == 1:
        units = units * n_points
    elif len(units) < n_points:
        notes.append(
            f"POINT:UNITS gives {len(units)} units for {n_points} points; the rest taken as the last"
        )
        units = units + [units[-1]] * (n_points - len(units))
    if any(not u for u in units):
        notes.append("empty POINT:UNITS entries; assumed mm")
    scales = [
        unit_scale(u or "mm", src, f"parameter POINT:UNITS (point {i + 1})")
        for i, u in enumerate(units[:n_points])
    ]
    if len(set(units[:n_points])) > 1:
        notes.append("POINT:UNITS differs between points: " + ", ".join(sorted(set(units))))
    return np.asarray(scales, dtype=float)


def read_c3d(path: str | os.PathLike[str]) -> Take:
    import c3d

    src = str(path)
    notes: list[str] = []
    try:
        with open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader = c3d.Reader(fh)
            n_points = int(reader.point_used or 0)
            if n_points == 0:
                raise InputError(
                    "no marker positions: the file holds no 3D points (POINT:USED = 0), only "
                    "rotations or analog channels; export the marker trajectories",
                    source=src,
                )
            labels = _labels(reader)
            scale = _point_units(reader, n_points, src, notes)
            rate = float(reader.point_rate or 0.0)
            frames = [
                np.asarray(p, dtype=float)[:, :4]
                for _, p, _ in reader.read_frames(copy=True)
                if p is not None
            ]
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=src) from None
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - the library raises assorted errors on corrupt files
        raise InputError(f"not a readable C3D file: {exc}", source=src) from None
    if not frames:
        raise InputError("no frames of 3D points in the file", source=src)
    if len(labels) < n_points:
        notes.append(
            f"POINT:LABELS names {len(labels)} of {n_points} points; the rest are called P<n>"
        )
        labels += [f"P{i + 1}" for i in range(len(labels), n_points)]
    labels = labels[:n_points]
    names, keep = _unique(labels, notes)
    data = np.array(frames, dtype=float).reshape(len(frames), n_points, 4)[:, keep]
    positions = data[..., :3] * scale[keep][None, :, None]
    positions[data[..., 3] < 0] = np.nan
    times = np.arange(len(frames)) / rate if rate > 0 else np.arange(len(frames), dtype=float)
    if not rate > 0:
        notes.append("POINT:RATE is not positive; times are frame numbers")
    return Take(tuple(names), positions, times, src, FORMAT, tuple(notes))


def _unique(labels: list[str], notes: list[str]) -> tuple[list[str], list[int]]:
    names: list[str] = []
    keep: list[int] = []
    for i, label in enumerate(labels):
        if label in names:
            notes.append(f"duplicate point label {label}; kept the first")
            continue
        names.append(label)
        keep.append(i)
    return names, keep


def write_c3d(
    path: str | os.PathLike[str],
    take: Take,
    *,
    units: str | Sequence[str] = "mm",
    rate_hz: float | None = None,
) -> None:
    """Write ``take`` as a float C3D file (gaps get residual -1), atomically. ``units``: one
    unit for every point, or one per point (written as a POINT:UNITS array)."""
    import c3d

    per_point = not isinstance(units, str)
    unit_list = list(units) if per_point else [str(units)] * len(take.marker_names)
    scale = np.array([unit_scale(u, str(path), "units") for u in unit_list])
    rate = rate_hz if rate_hz is not None else _rate_of(take.times_s)
    writer = c3d.Writer(point_rate=float(rate), point_units=unit_list[0].ljust(4))
    writer.set_point_labels(list(take.marker_names))
    if per_point:
        width = max(4, *(len(u) for u in unit_list))
        packed = "".join(u.ljust(width) for u in unit_list)
        writer.point_group.add_str("UNITS", "Units of each point.", packed, width, len(unit_list))
    pts = np.zeros((take.n_frames, len(take.marker_names), 5), dtype=np.float32)
    gap = np.isnan(take.positions).any(axis=2)
    pts[..., :3] = np.where(gap[..., None], 0.0, take.positions / scale[None, :, None])
    pts[..., 3] = np.where(gap, -1.0, 0.0)
    pts[..., 4] = np.where(gap, 0.0, 7.0)  # three cameras saw it
    empty = np.zeros((0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        writer.add_frames([(p, empty) for p in pts])
        with atomic_open(path, "wb") as fh:
            writer.write(fh)


def _rate_of(times_s: np.ndarray) -> float:
    if len(times_s) > 1:
        dt = float(np.median(np.diff(times_s)))
        if dt > 0:
            return 1.0 / dt
    return 120.0
