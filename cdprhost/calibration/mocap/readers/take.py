"""One motion-capture take as arrays, and the small parsing helpers every reader shares."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cdprhost.errors import InputError

FORMATS = ("motive-csv", "vicon-csv", "qualisys-tsv", "c3d")

# Length unit names as the exporters spell them -> millimetres per unit.
UNIT_TO_MM = {
    "millimeters": 1.0,
    "millimetres": 1.0,
    "millimeter": 1.0,
    "mm": 1.0,
    "centimeters": 10.0,
    "centimetres": 10.0,
    "centimeter": 10.0,
    "cm": 10.0,
    "meters": 1000.0,
    "metres": 1000.0,
    "meter": 1000.0,
    "m": 1000.0,
}


@dataclass(frozen=True, eq=False)
class Take:
    """Marker trajectories of one take: ``positions`` (frames, markers, 3) in mm, NaN = gap."""

    marker_names: tuple[str, ...]
    positions: np.ndarray
    times_s: np.ndarray
    source: str
    format: str
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, dtype=float)
        if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[1] != len(self.marker_names):
            raise ValueError(
                f"positions must be (frames, {len(self.marker_names)}, 3), got {pos.shape}"
            )
        times = np.asarray(self.times_s, dtype=float).reshape(-1)
        if times.shape[0] != pos.shape[0]:
            raise ValueError(f"times_s has {times.shape[0]} entries for {pos.shape[0]} frames")
        if len(set(self.marker_names)) != len(self.marker_names):
            raise ValueError("marker names must be unique")
        object.__setattr__(self, "marker_names", tuple(self.marker_names))
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "times_s", times)

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    def index(self, name: str) -> int:
        """Column of marker ``name``; InputError naming the take and the marker if absent."""
        try:
            return self.marker_names.index(name)
        except ValueError:
            shown = ", ".join(self.marker_names[:20]) + (
                " ..." if len(self.marker_names) > 20 else ""
            )
            raise InputError(
                f"marker '{name}' not in take (markers: {shown or 'none'})", source=self.source
            ) from None

    def marker(self, name: str) -> np.ndarray:
        """Trajectory of one marker, (frames, 3)."""
        return self.positions[:, self.index(name)]

    def select(self, names: Sequence[str]) -> np.ndarray:
        """Trajectories of several markers, (frames, len(names), 3)."""
        return self.positions[:, [self.index(n) for n in names]]


def unit_scale(name: str, source: str, where: str) -> float:
    """Millimetres per unit for an exporter's unit name."""
    try:
        return UNIT_TO_MM[name.strip().lower()]
    except KeyError:
        known = "Meters, Centimeters, Millimeters (or m, cm, mm)"
        raise InputError(
            f"{where}: unknown length unit {name!r} (expected {known})", source=source
        ) from None


def read_text(path: str | os.PathLike[str]) -> str:
    """Whole file as text (UTF-8, BOM tolerated; Latin-1 fallback for old exports)."""
    src = str(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=src) from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def sniff_delimiter(text: str, lines: int = 12) -> str:
    """``;`` for exports written with European locale settings (where ``,`` is the decimal
    separator), else ``,``: whichever of the two is more frequent in the first lines."""
    head = "\n".join(text.splitlines()[:lines])
    return ";" if head.count(";") > head.count(",") else ","


def csv_rows(text: str) -> list[list[str]]:
    """Rows of a comma- or semicolon-separated export (:func:`sniff_delimiter`)."""
    return list(csv.reader(io.StringIO(text), delimiter=sniff_delimiter(text)))


def to_float(cell: str) -> float:
    """A number as exporters write it: ``.`` or (European locale) ``,`` as decimal separator."""
    return float(cell.strip().replace(",", "."))


def numeric_block(
    rows: Sequence[Sequence[str]],
    columns: Sequence[int],
    *,
    first_line: int,
    column_label: Callable[[int], str],
    source: str,
    line_numbers: Sequence[int] | None = None,
) -> np.ndarray:
    """Cells ``rows[i][columns[j]]`` as float (len(rows), len(columns)); empty or missing cells -> NaN.

    ``column_label(j)`` names column j in errors; rows are numbered from ``first_line``
    unless ``line_numbers`` gives each row's file line. A decimal comma is accepted.
    """
    cols = np.asarray(columns, dtype=int)
    width = int(cols.max()) + 1 if cols.size else 0
    cells = np.full((len(rows), width), "", dtype=object)
    for i, row in enumerate(rows):
        n = min(len(row), width)
        cells[i, :n] = row[:n]
    picked = cells[:, cols] if cols.size else np.empty((len(rows), 0), dtype=object)
    text = np.char.strip(picked.astype(str)) if picked.size else picked.astype(str)
    text = np.where(text == "", "nan", text)
    # a comma inside a cell can only be a decimal comma (European locale exports)
    text = np.char.replace(text, ",", ".") if text.size else text
    try:
        values = text.astype(float)
        bad = np.isinf(values)
    except ValueError:
        values, bad = None, None
    if values is not None and not bad.any():
        return values
    for i in range(text.shape[0]):  # slow path, only to name the offending cell
        for j in range(text.shape[1]):
            cell = str(text[i, j])
            try:
                ok = not np.isinf(float(cell))
            except ValueError:
                ok = False
            if not ok:
                line = line_numbers[i] if line_numbers is not None else first_line + i
                raise InputError(
                    f"line {line}, column {cols[j] + 1} ({column_label(j)}): not a finite number: {cell!r}",
                    source=source,
                )
    raise AssertionError("unreachable")
