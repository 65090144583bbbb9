"""Numeric CSV tables <-> numpy arrays, with errors naming file, row and column."""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence

import numpy as np

from cdprhost.errors import InputError
from cdprhost.fileio.atomic import atomic_open


def read_columns(path: str | os.PathLike[str], columns: Sequence[str]) -> np.ndarray:
    """Read the named columns (others ignored) as float64 (N, len(columns)).

    Row numbers in errors are file line numbers (the header is row 1).
    """
    src = str(path)
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            text = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=src) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", source=src) from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError("empty file: expected a header row " + ",".join(columns), source=src)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in columns if c not in header]
    if missing:
        raise InputError(
            f"row 1: header lacks column(s) {', '.join(missing)} (expected {','.join(columns)}, got {','.join(header)})",
            source=src,
        )
    idx = [header.index(c) for c in columns]
    out = np.empty((len(rows) - 1, len(columns)))
    n = 0
    for r, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        for j, (c, i) in enumerate(zip(columns, idx)):
            cell = row[i].strip() if i < len(row) else ""
            try:
                v = float(cell)
            except ValueError:
                raise InputError(
                    f"row {r}, column '{c}': not a number: {cell!r}", source=src
                ) from None
            if not math.isfinite(v):
                raise InputError(
                    f"row {r}, column '{c}': not a finite number: {cell!r}", source=src
                )
            out[n, j] = v
        n += 1
    return out[:n]


def data_row_numbers(path: str | os.PathLike[str]) -> np.ndarray:
    """File row number of each non-blank data row (to name rows in later errors)."""
    with open(path, encoding="utf-8", newline="") as fh:
        rows = list(csv.reader(fh))
    return np.array(
        [r for r, row in enumerate(rows[1:], start=2) if row and any(c.strip() for c in row)],
        dtype=int,
    )


def write_columns(
    path: str | os.PathLike[str],
    header: Sequence[str],
    columns: Sequence[np.ndarray],
    fmts: Sequence[str],
) -> None:
    """Write equal-length columns atomically; ``fmts`` are %-formats per column."""
    table = np.column_stack([np.asarray(c) for c in columns]) if columns else np.empty((0, 0))
    buf = io.StringIO()
    buf.write(",".join(header) + "\n")
    if len(table):
        np.savetxt(buf, table, fmt=list(fmts), delimiter=",")
    with atomic_open(path, "w") as fh:
        fh.write(buf.getvalue())
