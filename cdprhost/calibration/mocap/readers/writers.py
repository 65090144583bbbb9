"""Write a :class:`Take` in each exporter's layout (virtual mocap, synthetic sessions, tests).

The files follow the real exports closely enough for the readers (and for the
exporters' own habits: Motive's rigid-body columns before the markers, Nexus CRLF,
QTM's 0,0,0 gaps). Every write is atomic.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from cdprhost.calibration.mocap.readers.c3d_take import write_c3d
from cdprhost.calibration.mocap.readers.motive import SUPPORTED_VERSIONS
from cdprhost.calibration.mocap.readers.take import FORMATS, Take, unit_scale
from cdprhost.fileio.atomic import write_text_atomic

MOTIVE_UNITS = ("Meters", "Centimeters", "Millimeters")


def _fmt(values: np.ndarray, spec: str, gap: str = "") -> np.ndarray:
    """Format a float array elementwise; NaN -> ``gap``."""
    out = np.char.mod(spec, np.nan_to_num(values))
    return np.where(np.isnan(values), gap, out)


def _rate_of(take: Take, rate_hz: float | None) -> float:
    if rate_hz is not None:
        return float(rate_hz)
    if take.n_frames > 1:
        dt = float(np.median(np.diff(take.times_s)))
        if dt > 0:
            return 1.0 / dt
    return 120.0


def _join(table: np.ndarray, sep: str) -> list[str]:
    return [sep.join(row) for row in table.tolist()]


def _european_line(line: str) -> str:
    """A comma-separated line as European locale settings write it: ``;`` between cells,
    decimal commas in numbers."""
    cells = line.split(",")
    out = []
    for c in cells:
        try:
            float(c)
            out.append(c.replace(".", ","))
        except ValueError:
            out.append(c)
    return ";".join(out)


def _european_table(table: np.ndarray) -> list[str]:
    return _join(np.char.replace(table.astype(str), ".", ","), ";")


def write_motive(
    path: str | os.PathLike[str],
    take: Take,
    *,
    version: str = "1.23",
    units: str = "Millimeters",
    rigid_bodies: Mapping[str, Sequence[str]] | None = None,
    rate_hz: float | None = None,
    take_name: str = "Take 001",
    european: bool = False,
) -> None:
    """Motive CSV of format ``version`` (1.21-1.25) in ``units`` (Meters/Centimeters/Millimeters).

    ``rigid_bodies`` maps a rigid-body name to its member markers: each gets Rigid Body
    columns (identity rotation, members' centroid, mean marker error) and Rigid Body
    Marker columns (the members' take-averaged positions), placed before the markers.
    1.25 adds the Parent row; 1.21 has no blank line after the first line. ``european``:
    ``;`` separators and decimal commas (Motive on a European locale).
    """
    if version not in SUPPORTED_VERSIONS:
        raise ValueError(f"Motive version must be one of {SUPPORTED_VERSIONS}, got {version!r}")
    if units not in MOTIVE_UNITS:
        raise ValueError(f"Motive units must be one of {MOTIVE_UNITS}, got {units!r}")
    scale = unit_scale(units, str(path), "units")
    rate = _rate_of(take, rate_hz)
    n = take.n_frames
    meta = ["Format Version", version, "Take Name", take_name]
    if version >= "1.23":
        meta += ["Take Notes", ""]
    meta += [
        "Capture Frame Rate",
        f"{rate:.6f}",
        "Export Frame Rate",
        f"{rate:.6f}",
        "Capture Start Time",
        "2024-01-01 12.00.00.000 PM",
    ]
    if version >= "1.23":
        meta += ["Capture Start Frame", "0"]
    meta += [
        "Total Frames in Take",
        str(n),
        "Total Exported Frames",
        str(n),
        "Rotation Type",
        "Quaternion",
        "Length Units",
        units,
        "Coordinate Space",
        "Global",
    ]

    types, names, ids, parents, labels, axes = [], [], [], [], [], []
    blocks: list[np.ndarray] = []  # (n, width) string blocks in column order

    def add(
        kind: str,
        name: str,
        ident: str,
        parent: str,
        cols: Sequence[tuple[str, str]],
        block: np.ndarray,
    ) -> None:
        for label, axis in cols:
            types.append(kind)
            names.append(name)
            ids.append(ident)
            parents.append(parent)
            labels.append(label)
            axes.append(axis)
        blocks.append(block)

    for k, (rb, members) in enumerate((rigid_bodies or {}).items(), start=1):
        pts = take.select(list(members))
        with warnings.catch_warnings():  # all-gap members: mean of empty slice
            warnings.simplefilter("ignore", RuntimeWarning)
            centre = np.nanmean(pts, axis=1) / scale
            solved = np.nanmean(pts, axis=0) / scale
        rot = np.tile(["0.000000", "0.000000", "0.000000", "1.000000"], (n, 1))
        err = np.where(np.isnan(centre[:, :1]), "", f"{0.00012 * 1000.0 / scale:.6f}")
        add(
            "Rigid Body",
            rb,
            str(k),
            "",
            [("Rotation", a) for a in "XYZW"]
            + [("Position", a) for a in "XYZ"]
            + [("Mean Marker Error", "")],
            np.hstack([rot, _fmt(centre, "%.6f"), err]),
        )
        for i, m in enumerate(members):
            block = np.hstack(
                [np.tile(_fmt(solved[i], "%.6f"), (n, 1)), np.full((n, 1), "1.000000")]
            )
            add(
                "Rigid Body Marker",
                m,
                f"{k}:{i + 1}",
                rb,
                [("Position", a) for a in "XYZ"] + [("Marker Quality", "")],
                block,
            )
    for i, m in enumerate(take.marker_names):
        parent = m.split(":")[0] if ":" in m else ""
        add(
            "Marker",
            m,
            f"{1000 + i}",
            parent,
            [("Position", a) for a in "XYZ"],
            _fmt(take.positions[:, i] / scale, "%.6f"),
        )

    head = [",".join(meta)]
    if version != "1.21":
        head.append("")
    head += [",Type," + ",".join(types), ",Name," + ",".join(names), ",ID," + ",".join(ids)]
    if version >= "1.25":
        head.append(",Parent," + ",".join(parents))
    head += [",," + ",".join(labels), "Frame,Time (Seconds)," + ",".join(axes)]
    lead = np.column_stack([np.arange(n).astype(str), _fmt(take.times_s, "%.6f")])
    table = np.hstack([lead, *blocks])
    if european:
        head, body = [_european_line(h) for h in head], _european_table(table)
    else:
        body = _join(table, ",")
    write_text_atomic(path, "\r\n".join(head + body) + "\r\n")


def write_vicon(
    path: str | os.PathLike[str],
    take: Take,
    *,
    rate_hz: float | None = None,
    units: str = "mm",
    devices_section: bool = False,
    european: bool = False,
) -> None:
    """Vicon Nexus CSV (CRLF): optional empty ``Devices`` section, then ``Trajectories``;
    ``european``: ``;`` separators and decimal commas."""
    scale = unit_scale(units, str(path), "units")
    rate = _rate_of(take, rate_hz)
    m = len(take.marker_names)
    lines: list[str] = []
    if devices_section:  # one idle force-plate channel at twice the frame rate
        lines += [
            "Devices",
            f"{2 * rate:g}",
            ",,Imported Force Plate #1 - Force,,",
            "Frame,Sub Frame,Fx,Fy,Fz",
            ",,N,N,N",
        ]
        lines += [f"{f + 1},{s},0,0,0" for f in range(take.n_frames) for s in range(2)]
        lines.append("")
    lines += ["Trajectories", f"{rate:g}"]
    lines.append(",," + ",".join(f"{name},," for name in take.marker_names))
    lines.append("Frame,Sub Frame," + ",".join(["X,Y,Z"] * m))
    lines.append(",," + ",".join([units] * 3 * m))
    n = take.n_frames
    lead = np.column_stack([(np.arange(n) + 1).astype(str), np.full(n, "0")])
    values = _fmt(take.positions.reshape(n, 3 * m) / scale, "%.5f")
    if european:
        lines = [_european_line(x) for x in lines]
        lines += _european_table(np.hstack([lead, values]))
    else:
        lines += _join(np.hstack([lead, values]), ",")
    lines.append("")
    write_text_atomic(path, "\r\n".join(lines) + "\r\n")


def write_qualisys(
    path: str | os.PathLike[str],
    take: Take,
    *,
    rate_hz: float | None = None,
    column_header: bool = True,
    zero_gaps: bool = True,
) -> None:
    """QTM 3D TSV in mm; gaps as 0,0,0 (``zero_gaps``) or empty cells."""
    rate = _rate_of(take, rate_hz)
    n, m = take.n_frames, len(take.marker_names)
    lines = [
        f"NO_OF_FRAMES\t{n}",
        "NO_OF_CAMERAS\t8",
        f"NO_OF_MARKERS\t{m}",
        f"FREQUENCY\t{rate:g}",
        "NO_OF_ANALOG\t0",
        "ANALOG_FREQUENCY\t0",
        "DESCRIPTION\t--",
        "TIME_STAMP\t2024-01-01, 12:00:00.000\t1000.000",
        "DATA_INCLUDED\t3D",
        "MARKER_NAMES\t" + "\t".join(take.marker_names),
        "TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * m),
    ]
    gap = "0.000" if zero_gaps else ""
    values = _fmt(take.positions.reshape(n, 3 * m), "%.3f", gap)
    if column_header:
        lines.append(
            "Frame\tTime\t" + "\t".join(f"{name} {a}" for name in take.marker_names for a in "XYZ")
        )
        lead = np.column_stack([(np.arange(n) + 1).astype(str), _fmt(take.times_s, "%.5f")])
        values = np.hstack([lead, values])
    lines += _join(values, "\t")
    write_text_atomic(path, "\n".join(lines) + "\n")


def write_take(path: str | os.PathLike[str], take: Take, format: str, **options: Any) -> None:
    """Write ``take`` as ``format`` (one of FORMATS) with that writer's ``options``."""
    writers: dict[str, Callable[..., None]] = {
        "motive-csv": write_motive,
        "vicon-csv": write_vicon,
        "qualisys-tsv": write_qualisys,
        "c3d": write_c3d,
    }
    if format not in writers:
        raise ValueError(f"unknown take format {format!r} (expected one of {', '.join(FORMATS)})")
    writers[format](path, take, **options)


EXTENSIONS = {"motive-csv": ".csv", "vicon-csv": ".csv", "qualisys-tsv": ".tsv", "c3d": ".c3d"}
