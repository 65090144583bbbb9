"""OptiTrack Motive CSV export (format versions 1.21 to 1.25) -> :class:`Take`.

Layout: a first line of key,value pairs (``Format Version``, ``Capture Frame Rate``,
``Length Units`` ...), optionally a blank line, then header rows whose second cell
names them (``Type``, ``Name``, ``ID``, and from 1.25 ``Parent``), a row of
``Rotation`` / ``Position`` / ``Mean Marker Error`` / ``Marker Quality`` labels, the
``Frame,Time (Seconds),X,Y,Z,...`` row, and data. Exports made with European locale
settings separate with ``;`` and write decimal commas; both are read. Only columns of Type ``Marker`` and
label ``Position`` are read, by name: Rigid Body and Rigid Body Marker columns are
skipped (a rigid body's solved markers repeat the measured markers' names).
"""

from __future__ import annotations

import os

import numpy as np

from cdprhost.calibration.mocap.readers.take import (
    Take,
    csv_rows,
    numeric_block,
    read_text,
    to_float,
    unit_scale,
)
from cdprhost.errors import InputError

FORMAT = "motive-csv"
SUPPORTED_VERSIONS = ("1.21", "1.22", "1.23", "1.24", "1.25")
HEADER_KEYS = ("Type", "Name", "ID", "Parent")


def looks_like_motive(first_line: str) -> bool:
    head = first_line.lstrip("\ufeff")
    return head.startswith(("Format Version,", "Format Version;"))


def parse_metadata(cells: list[str]) -> dict[str, str]:
    """The first line's key,value pairs."""
    return {
        cells[i].strip(): cells[i + 1].strip()
        for i in range(0, len(cells) - 1, 2)
        if cells[i].strip()
    }


def read_motive(path: str | os.PathLike[str]) -> Take:
    return parse_motive(read_text(path), str(path))


def parse_motive(text: str, source: str) -> Take:
    rows = csv_rows(text)
    if not rows or not rows[0] or rows[0][0].strip() != "Format Version":
        raise InputError(
            "line 1: not a Motive CSV export (expected 'Format Version,...')", source=source
        )
    meta = parse_metadata(rows[0])
    notes: list[str] = []
    version = meta.get("Format Version", "").replace(",", ".")
    if version not in SUPPORTED_VERSIONS:
        notes.append(f"Motive format version {version!r} is outside 1.21-1.25; read as 1.23")
    if "Length Units" in meta:
        scale = unit_scale(meta["Length Units"], source, "line 1, key 'Length Units'")
    else:
        scale = 1000.0
        notes.append("no 'Length Units' on line 1; assumed Meters (Motive's default)")

    axis_row = next(
        (i for i, r in enumerate(rows) if i > 0 and r and r[0].strip() == "Frame"), None
    )
    if axis_row is None:
        raise InputError("no 'Frame,Time (Seconds),X,Y,Z,...' header row found", source=source)
    header: dict[str, list[str]] = {}
    header_line: dict[str, int] = {}
    for i in range(1, axis_row):
        r = rows[i]
        if len(r) > 1 and not r[0].strip() and r[1].strip() in HEADER_KEYS:
            header[r[1].strip()] = r
            header_line[r[1].strip()] = i + 1
    for key in ("Type", "Name"):
        if key not in header:
            raise InputError(
                f"header lacks the ',{key},...' row (lines 2-{axis_row})", source=source
            )
    labels = rows[axis_row - 1] if axis_row >= 2 else []
    if not labels or labels[0].strip() or "Position" not in [c.strip() for c in labels]:
        raise InputError(
            f"line {axis_row}: expected the row of Rotation/Position labels above line {axis_row + 1}",
            source=source,
        )
    axes = rows[axis_row]

    def cell(row: list[str], j: int) -> str:
        return row[j].strip() if j < len(row) else ""

    columns: dict[str, dict[str, int]] = {}
    for j in range(2, len(axes)):
        if cell(header["Type"], j) != "Marker" or cell(labels, j) != "Position":
            continue
        axis = cell(axes, j)
        if axis not in ("X", "Y", "Z"):
            continue
        name = cell(header["Name"], j)
        if not name:
            raise InputError(
                f"line {header_line['Name']}, column {j + 1}: Marker column without a name",
                source=source,
            )
        slot = columns.setdefault(name, {})
        if axis in slot:
            if f"duplicate marker {name}" not in notes:
                notes.append(f"duplicate marker {name}")
            continue
        slot[axis] = j
    for name, slot in columns.items():
        missing = [a for a in "XYZ" if a not in slot]
        if missing:
            raise InputError(
                f"marker '{name}' lacks its Position {'/'.join(missing)} column(s)", source=source
            )
    if not columns:
        raise InputError(
            "no Marker position columns (export with Markers enabled, not only Rigid Bodies)",
            source=source,
        )

    names = tuple(columns)
    col_idx = [columns[n][a] for n in names for a in "XYZ"]
    data = [
        (i + 1, r)
        for i, r in enumerate(rows[axis_row + 1 :], start=axis_row + 1)
        if r and any(c.strip() for c in r)
    ]
    line_numbers = [n for n, _ in data]
    body = [r for _, r in data]
    labels_of = [f"{n} {a}" for n in names for a in "XYZ"]
    values = numeric_block(
        body,
        [0, 1, *col_idx],
        first_line=axis_row + 2,
        source=source,
        line_numbers=line_numbers,
        column_label=lambda j: (["Frame", "Time"] + labels_of)[j],
    )
    frames, times = values[:, 0], values[:, 1]
    if np.isnan(frames).any():
        bad = line_numbers[int(np.flatnonzero(np.isnan(frames))[0])]
        raise InputError(f"line {bad}, column 1 (Frame): empty", source=source)
    if np.isnan(times).any():
        rate = _frame_rate(meta)
        if rate is None:
            bad = line_numbers[int(np.flatnonzero(np.isnan(times))[0])]
            raise InputError(
                f"line {bad}, column 2 (Time): empty and no frame rate on line 1", source=source
            )
        times = (frames - frames[0]) / rate
    positions = values[:, 2:].reshape(len(body), len(names), 3) * scale
    return Take(names, positions, times, source, FORMAT, tuple(notes))


def _frame_rate(meta: dict[str, str]) -> float | None:
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        try:
            rate = to_float(meta[key])
        except (KeyError, ValueError):
            continue
        if rate > 0:
            return rate
    return None
