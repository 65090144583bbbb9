"""Qualisys QTM 3D TSV export -> :class:`Take`.

Tab-separated header lines (``NO_OF_FRAMES``, ``FREQUENCY``, ``MARKER_NAMES`` ...,
maybe ``TRAJECTORY_TYPES``), then either a column row ``Frame\\tTime\\tname X\\t...``
or the data directly (older exports: 3 columns per marker, possibly preceded by
frame and time). Coordinates are mm. A gap is an empty cell or 0,0,0.
"""

from __future__ import annotations

import os

import numpy as np

from cdprhost.calibration.mocap.readers.take import Take, numeric_block, read_text, to_float
from cdprhost.errors import InputError

FORMAT = "qualisys-tsv"


def looks_like_qualisys(first_line: str) -> bool:
    return first_line.lstrip("\ufeff").split("\t")[0].strip() == "NO_OF_FRAMES"


def read_qualisys(path: str | os.PathLike[str]) -> Take:
    return parse_qualisys(read_text(path), str(path))


def _is_header_key(cell: str) -> bool:
    return bool(cell) and cell.replace("_", "").isalpha() and cell.upper() == cell


def parse_qualisys(text: str, source: str) -> Take:
    lines = text.splitlines()
    rows = [line.split("\t") for line in lines]
    meta: dict[str, list[str]] = {}
    meta_line: dict[str, int] = {}
    i = 0
    while i < len(rows) and _is_header_key(rows[i][0].strip()):
        meta[rows[i][0].strip()] = [c.strip() for c in rows[i][1:]]
        meta_line[rows[i][0].strip()] = i + 1
        i += 1
    if "MARKER_NAMES" not in meta:
        raise InputError(
            "no MARKER_NAMES header line (export 3D data as TSV from QTM)", source=source
        )
    names = [n for n in meta["MARKER_NAMES"] if n]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(
            f"line {meta_line['MARKER_NAMES']}: marker '{dup}' named twice", source=source
        )
    if not names:
        raise InputError(
            f"line {meta_line['MARKER_NAMES']}: MARKER_NAMES lists no markers", source=source
        )
    rate = _float_meta(meta, "FREQUENCY")
    notes: list[str] = []
    while i < len(rows) and not any(c.strip() for c in rows[i]):
        i += 1
    header = [c.strip() for c in rows[i]] if i < len(rows) else []
    if header and header[0] == "Frame":
        col_idx = []
        for n in names:
            for a in "XYZ":
                key = f"{n} {a}"
                if key not in header:
                    raise InputError(
                        f"line {i + 1}: no column '{key}' for marker '{n}'", source=source
                    )
                col_idx.append(header.index(key))
        frame_col = 0
        time_col = header.index("Time") if "Time" in header else None
        i += 1
    else:
        width = max((len(r) for r in rows[i:] if any(c.strip() for c in r)), default=0)
        lead = width - 3 * len(names)
        if lead not in (0, 2):
            raise InputError(
                f"line {i + 1}: {width} columns for {len(names)} markers (expected {3 * len(names)} or {3 * len(names) + 2})",
                source=source,
            )
        col_idx = [lead + k for k in range(3 * len(names))]
        frame_col, time_col = (0, 1) if lead == 2 else (None, None)  # type: ignore[assignment]

    data = [(n + 1, r) for n, r in enumerate(rows[i:], start=i) if any(c.strip() for c in r)]
    body = [r for _, r in data]
    lines_of = [n for n, _ in data]
    extra = [c for c in (frame_col, time_col) if c is not None]
    labels = [f"{n} {a}" for n in names for a in "XYZ"] + ["Frame", "Time"][: len(extra)]
    values = numeric_block(
        body,
        [*col_idx, *extra],
        first_line=i + 1,
        line_numbers=lines_of,
        source=source,
        column_label=lambda j: labels[j],
    )
    positions = values[:, : 3 * len(names)].reshape(len(body), len(names), 3)
    positions[np.all(positions == 0.0, axis=2)] = np.nan
    if time_col is not None and not np.isnan(values[:, -1]).any():
        times = values[:, -1]
    elif rate is not None:
        times = np.arange(len(body)) / rate
    else:
        raise InputError(
            "no Time column and no FREQUENCY header line: cannot time the frames", source=source
        )
    declared = _float_meta(meta, "NO_OF_FRAMES")
    if declared is not None and int(declared) != len(body):
        notes.append(f"NO_OF_FRAMES says {int(declared)}, file has {len(body)} data rows")
    return Take(tuple(names), positions, times, source, FORMAT, tuple(notes))


def _float_meta(meta: dict[str, list[str]], key: str) -> float | None:
    try:
        value = to_float(meta[key][0])
    except (KeyError, IndexError, ValueError):
        return None
    return value if value > 0 else None
