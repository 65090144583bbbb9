"""Printable boards: a ChArUco board laid out on a sheet of paper at its exact size.

Pure: the board's pixels (:func:`board_pixels`), where the board, its title and a ruler
scale bar sit on the page (:func:`sheet_layout`, or :class:`DoesNotFit` naming the
room the board needs) and the ``[camera.*_board]`` tables that describe what was printed
(:func:`config_block`). Drawing the sheet into a PDF or PNG is the caller's (a thin
shell over matplotlib); nothing here reads or writes files.

Page coordinates are millimetres from the page's lower-left corner, x to the right and
y up (a plotting library's). The board's image has its first row at the top, as OpenCV
draws it and as the board frame (camera-session.md) has it: x along the rows, y down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard

MM_PER_INCH = 25.4
CAMERA_FILE = "camera.toml"
EDGE_MM = 10.0  # kept free at every paper edge: many printers cannot print the outer 5 mm
QUIET_MM = 6.0  # white between the board and anything else printed
TITLE_MM = 12.0  # two lines of text above the board
SCALE_MM = 16.0  # the scale bar and its label below the board
SCALE_BAR_HEIGHT_MM = 3.0
MIN_SCALE_BAR_MM = 50.0
MIN_SQUARE_MM = 4.0  # smaller markers blur into the paper on office printers
MAX_SCALE_BAR_MM = 150.0
DEFAULT_TEXEL_DPI = 600.0  # the board image's resolution in a PDF (the viewer scales it)


@dataclass(frozen=True)
class Paper:
    name: str
    width_mm: float  # portrait
    height_mm: float


PAPERS: dict[str, Paper] = {
    "a4": Paper("A4", 210.0, 297.0),
    "letter": Paper("Letter", 215.9, 279.4),
}


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle on the page (mm)."""

    x: float
    y: float
    width: float
    height: float


@dataclass(frozen=True)
class SheetLayout:
    """One board on one page: where each printed part sits (page mm, y up)."""

    paper: Paper
    landscape: bool
    board: Rect  # the board's outer edge (squares_x * square_mm by squares_y * square_mm)
    scale_bar: Rect  # the bar; its length is a whole number of centimetres
    title_xy: tuple[float, float]  # the title's upper-left corner
    label_xy: tuple[float, float]  # the scale bar label's upper-left corner

    @property
    def page_mm(self) -> tuple[float, float]:
        p = self.paper
        return (p.height_mm, p.width_mm) if self.landscape else (p.width_mm, p.height_mm)

    @property
    def scale_bar_mm(self) -> float:
        return self.scale_bar.width


class DoesNotFit(ValueError):
    """A board larger than the paper's printable area; the message says what it needs."""

    def __init__(self, board: CharucoBoard, paper: Paper, need_mm: tuple[float, float]):
        self.need_mm = need_mm
        w, h = board.size_mm
        room_w, room_h = paper.width_mm - 2 * EDGE_MM, paper.height_mm - 2 * EDGE_MM
        super().__init__(
            f"a board of {board.squares[0]} x {board.squares[1]} squares of "
            f"{board.square_mm:g} mm ({w:g} x {h:g} mm) does not fit {paper.name}: with its "
            f"white border, title and scale bar it needs {need_mm[0]:.1f} x {need_mm[1]:.1f} mm "
            f"inside the {EDGE_MM:g} mm paper edges (a sheet of at least "
            f"{need_mm[0] + 2 * EDGE_MM:.0f} x {need_mm[1] + 2 * EDGE_MM:.0f} mm); "
            f"{paper.name} gives {room_w:.1f} x {room_h:.1f} mm (either way round): "
            f"use larger paper or smaller squares"
        )


def needed_area_mm(board: CharucoBoard) -> tuple[float, float]:
    """Width and height of the printable area the board's sheet needs (mm)."""
    w, h = board.size_mm
    width = max(w, MIN_SCALE_BAR_MM) + 2 * QUIET_MM
    height = TITLE_MM + QUIET_MM + h + QUIET_MM + SCALE_MM
    return width, height


def sheet_layout(board: CharucoBoard, paper: Paper) -> SheetLayout:
    """The board centred on ``paper`` (portrait when it fits, else landscape), the title
    above it and a scale bar below; :class:`DoesNotFit` when neither way fits."""
    if board.square_mm < MIN_SQUARE_MM:
        raise ValueError(
            f"squares of {board.square_mm:g} mm are too small to print and detect reliably "
            f"(at least {MIN_SQUARE_MM:g} mm)"
        )
    need_w, need_h = needed_area_mm(board)
    for landscape in (False, True):
        page_w, page_h = (
            (paper.height_mm, paper.width_mm) if landscape else (paper.width_mm, paper.height_mm)
        )
        room_w, room_h = page_w - 2 * EDGE_MM, page_h - 2 * EDGE_MM
        if need_w <= room_w + 1e-9 and need_h <= room_h + 1e-9:
            break
    else:
        raise DoesNotFit(board, paper, (need_w, need_h))
    w, h = board.size_mm
    top = EDGE_MM + (room_h - need_h) / 2 + need_h  # the block's top, centred vertically
    board_rect = Rect((page_w - w) / 2, top - TITLE_MM - QUIET_MM - h, w, h)
    bar_mm = float(min(MAX_SCALE_BAR_MM, 10 * math.floor(min(room_w, max(w, 100.0)) / 10)))
    bar_y = board_rect.y - QUIET_MM - SCALE_BAR_HEIGHT_MM
    bar = Rect((page_w - bar_mm) / 2, bar_y, bar_mm, SCALE_BAR_HEIGHT_MM)
    return SheetLayout(
        paper=paper,
        landscape=landscape,
        board=board_rect,
        scale_bar=bar,
        title_xy=(board_rect.x, top),
        label_xy=(bar.x, bar_y - 3.0),
    )


def board_pixels(board: CharucoBoard, texel_dpi: float = DEFAULT_TEXEL_DPI) -> np.ndarray:
    """The board's printed face as a uint8 grey image (rows top to bottom) with a whole
    number of pixels per square, at least ``texel_dpi`` per inch: every square edge falls
    on a pixel edge, so the image's extent is the board's size exactly."""
    sx, sy = board.squares
    per_square = max(int(math.ceil(board.square_mm / MM_PER_INCH * texel_dpi)), 24)
    for _ in range(16):  # OpenCV refuses some sizes (a rounding inside its drawing)
        try:
            img = board.cv_board.generateImage(
                (sx * per_square, sy * per_square), marginSize=0, borderBits=1
            )
        except cv2.error:
            per_square += 1
            continue
        return np.ascontiguousarray(img, dtype=np.uint8)
    raise ValueError(f"OpenCV cannot draw {board} at about {texel_dpi:g} dpi")


def board_rectangles(board: CharucoBoard, texel_dpi: float = DEFAULT_TEXEL_DPI) -> np.ndarray:
    """The board's ink as rectangles ``(x, y, width, height)`` in the board frame (mm, y
    down from the board's upper-left corner), (n, 4): :func:`board_pixels` cut into bands
    of identical rows, each band's dark runs one rectangle. Drawn as vectors, a sheet
    keeps every square edge exact at any printer's or rasteriser's resolution."""
    img = board_pixels(board, texel_dpi)
    pitch = board.square_mm / (img.shape[1] // board.squares[0])  # mm per pixel
    dark = img < 128
    starts = np.flatnonzero(np.r_[True, np.any(dark[1:] != dark[:-1], axis=1)])
    ends = np.r_[starts[1:], dark.shape[0]]
    bands = []
    for top, bottom in zip(starts, ends):
        edges = np.diff(np.r_[0, dark[top].astype(np.int8), 0])
        x0, x1 = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        band = np.empty((x0.size, 4))
        band[:, 0], band[:, 1], band[:, 2], band[:, 3] = x0, top, x1 - x0, bottom - top
        bands.append(band)
    return np.vstack(bands) * pitch


def sheet_title(name: str, board: CharucoBoard) -> tuple[str, str]:
    """The two lines printed above a board: what it is, and how to print it."""
    sx, sy = board.squares
    ids = board.marker_ids
    layout = ", legacy layout" if board.legacy_pattern else ""
    w, h = board.size_mm
    what = (
        f"cdprhost {name} board: {sx} x {sy} squares of {board.square_mm:g} mm, markers "
        f"{board.marker_mm:g} mm, {board.dictionary} ids {ids[0]}-{ids[-1]}{layout}"
    )
    how = (
        f"Print at 100 % (actual size, no fit to page). Board {w:g} x {h:g} mm; "
        "check the scale bar with a ruler before use."
    )
    return what, how


def scale_bar_label(bar_mm: float) -> str:
    tol = bar_mm * 1e-3
    return (
        f"{bar_mm:g} mm between the end ticks: a ruler must read {bar_mm - tol:.1f} to "
        f"{bar_mm + tol:.1f} mm (0.1 %), else the printer scaled the page"
    )


def config_block(tables: dict[str, dict[str, Any]]) -> str:
    """``[camera.<name>]`` TOML tables for the boards printed (keys as camera-session.md),
    with comments on what to measure after mounting. ``tables`` maps a table name
    (``reference_board``, ``effector_board``, ``calibration_board``) to its keys."""
    notes = {
        "origin": "measure after mounting: the board frame's origin in the base frame (mm)",
        "rotation_deg": "[180, 0, 0]: face-up on the base",
        "offset": "measure after mounting: B in the board's own frame (mm)",
        "offset_sigma_mm": "how well that offset is known (mm per coordinate)",
    }
    lines = [
        "# The boards printed by `cdprhost calibrate boards`: the [camera] section of a",
        "# session.toml (docs/camera-session.md), also usable as the wizard's --camera-config.",
        "# Sizes are as printed; measure a printed square with calipers and correct",
        "# square_mm and marker_mm if the printer scaled the page.",
        "",
        "[camera]",
        f"{'intrinsics = ' + _toml_value(CAMERA_FILE):<40}# from `cdprhost calibrate camera`, or:",
        f"{'# calibration_views = ' + _toml_value('intrinsics'):<40}# a folder of pictures",
    ]
    for name, table in tables.items():
        lines += ["", f"[camera.{name}]"]
        for key, value in table.items():
            text = f"{key} = {_toml_value(value)}"
            if key in notes:
                text = f"{text:<40}# {notes[key]}"
            lines.append(text)
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(float(value))
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")
