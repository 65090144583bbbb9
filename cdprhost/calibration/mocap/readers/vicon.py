"""Vicon Nexus CSV export -> :class:`Take` (the ``Trajectories`` section).

Layout of a section: its name (``Trajectories``), the frame rate, a row with a
``Subject:Marker`` name above each marker's X column, ``Frame,Sub Frame,X,Y,Z,...``,
a units row (``mm``), then data rows until a blank line. European locale exports
(``;`` separators, decimal commas) are read too. Other sections (``Devices``,
``Model Outputs``) may come before or after and are skipped. Gaps are empty cells.
"""

from __future__ import annotations

import os
import re

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

FORMAT = "vicon-csv"
SECTION = "trajectories"
KNOWN_SECTIONS = ("trajectories", "devices", "model outputs", "joints", "segments")


def _first(row: list[str]) -> str:
    return row[0].strip().lower() if row else ""


def looks_like_vicon(lines: list[str]) -> bool:
    """True if one of the first lines starts a Nexus section."""
    return any(re.split("[,;]", line)[0].strip().lower() in KNOWN_SECTIONS for line in lines)


def read_vicon(path: str | os.PathLike[str]) -> Take:
    return parse_vicon(read_text(path), str(path))


def parse_vicon(text: str, source: str) -> Take:
    rows = csv_rows(text)
    start = next((i for i, r in enumerate(rows) if _first(r) == SECTION), None)
    if start is None:
        raise InputError(
            "no 'Trajectories' section (export trajectories from Nexus)", source=source
        )
    if len(rows) < start + 5:
        raise InputError(f"line {start + 1}: 'Trajectories' section is truncated", source=source)
    try:
        rate = to_float(rows[start + 1][0])
        if not rate > 0:
            raise ValueError
    except (ValueError, IndexError):
        raise InputError(
            f"line {start + 2}: expected the frame rate (Hz) after 'Trajectories'", source=source
        ) from None
    names_row, axes_row = rows[start + 2], rows[start + 3]
    if _first(axes_row) != "frame":
        raise InputError(f"line {start + 4}: expected 'Frame,Sub Frame,X,Y,Z,...'", source=source)
    notes: list[str] = []
    units_row = rows[start + 4]
    has_units = bool(units_row) and not units_row[0].strip() and any(c.strip() for c in units_row)
    if not has_units:
        notes.append(f"line {start + 5}: no units row; assumed mm")

    def cell(row: list[str], j: int) -> str:
        return row[j].strip() if j < len(row) else ""

    names: list[str] = []
    col_idx: list[int] = []
    scales: list[float] = []
    for j in range(2, len(names_row)):
        name = cell(names_row, j)
        if not name:
            continue
        if [cell(axes_row, j + k) for k in range(3)] != ["X", "Y", "Z"]:
            continue  # velocity or other non-position columns
        if name in names:
            notes.append(f"duplicate marker {name}; kept the first")
            continue
        unit = cell(units_row, j) if has_units else "mm"
        scales.append(
            unit_scale(unit or "mm", source, f"line {start + 5}, column {j + 1} ({name})")
        )
        names.append(name)
        col_idx.extend([j, j + 1, j + 2])
    if not names:
        raise InputError(f"line {start + 3}: no marker names above X,Y,Z columns", source=source)

    first = start + (5 if has_units else 4)
    body: list[list[str]] = []
    for r in rows[first:]:
        if not r or not any(c.strip() for c in r):
            break
        body.append(r)
    labels = ["Frame"] + [f"{n} {a}" for n in names for a in "XYZ"]
    values = numeric_block(
        body, [0, *col_idx], first_line=first + 1, source=source, column_label=lambda j: labels[j]
    )
    frames = values[:, 0]
    if np.isnan(frames).any():
        bad = first + 1 + int(np.flatnonzero(np.isnan(frames))[0])
        raise InputError(f"line {bad}, column 1 (Frame): empty", source=source)
    positions = values[:, 1:].reshape(len(body), len(names), 3) * np.asarray(scales)[None, :, None]
    times = (frames - frames[0]) / rate if len(frames) else frames
    return Take(tuple(names), positions, times, source, FORMAT, tuple(notes))
