"""`cdprhost calibrate boards --out DIR [--paper a4|letter] [--png-dpi N]`: the session's
ChArUco boards as PDF (and PNG) sheets at their exact size, each with a scale bar to
check with a ruler, and the ``[camera.*_board]`` tables to paste into session.toml.

The boards come from ``--config`` (a session.toml, or any TOML with a ``[camera]``
section of board tables; default: the sample shipped with cdprhost). The layout and the
board's pixels are :mod:`cdprhost.calibration.camera.printable`'s; this shell draws them
with matplotlib and writes the files. Every board is laid out before anything is
written, so a board that does not fit the paper leaves nothing behind.
"""

from __future__ import annotations

import argparse
import io
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cdprhost.cli.options import output_folder
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import atomic_open, write_text_atomic

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.calibration.camera.boards import CharucoBoard
    from cdprhost.calibration.camera.printable import SheetLayout

BOARD_NAMES = ("reference", "effector", "calibration")
SAMPLE = "sample_boards.toml"  # in cdprhost/calibration/camera/
PNG_DPI_RANGE = (72, 1200)
CONFIG_FILE = "boards.toml"


def register(cal_sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    boards = cal_sub.add_parser(
        "boards",
        help="printable ChArUco boards (PDF, PNG) at their exact size, with a scale bar and "
        "the session.toml tables that describe them",
    )
    boards.add_argument(
        "--config",
        metavar="TOML",
        help="a session.toml (or any TOML with [camera.*_board] tables) whose boards to print "
        "(default: the sample shipped with cdprhost; see --show-sample)",
    )
    boards.add_argument(
        "--board",
        dest="which",
        action="append",
        choices=BOARD_NAMES,
        help="print only this board (repeatable; default: every board the config has)",
    )
    boards.add_argument(
        "--paper",
        choices=("a4", "letter"),
        default="a4",
        help="paper size (default a4); a board that fits only the other way round is "
        "printed landscape",
    )
    boards.add_argument(
        "--png-dpi",
        type=_png_dpi,
        metavar="DPI",
        help=f"also write each sheet as a PNG at DPI dots per inch "
        f"({PNG_DPI_RANGE[0]}-{PNG_DPI_RANGE[1]})",
    )
    boards.add_argument(
        "--out",
        type=output_folder,
        metavar="DIR",
        help="folder to write the sheets and boards.toml to (made if missing)",
    )
    boards.add_argument(
        "--show-sample",
        action="store_true",
        help="print the sample board configuration (a [camera] section) and exit",
    )
    boards.set_defaults(func=run_boards)


def _png_dpi(text: str) -> int:
    try:
        dpi = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    lo, hi = PNG_DPI_RANGE
    if not lo <= dpi <= hi:
        raise argparse.ArgumentTypeError(f"{dpi} dpi: must be {lo} to {hi}")
    return dpi


def sample_text() -> str:
    """The shipped sample configuration (a session.toml's [camera] section)."""
    return (
        resources.files("cdprhost.calibration.camera").joinpath(SAMPLE).read_text(encoding="utf-8")
    )


@dataclass(frozen=True)
class BoardToPrint:
    name: str  # reference | effector | calibration
    board: CharucoBoard
    table: dict[str, Any]  # its [camera.<name>_board] keys


def load_boards(config: str | None, which: list[str] | None) -> list[BoardToPrint]:
    """The boards of ``config``'s [camera] section (or the sample), validated."""
    import tomllib

    from pydantic import ValidationError

    from cdprhost.calibration.camera.config import (
        BoardConfig,
        EffectorBoardConfig,
        ReferenceBoardConfig,
    )
    from cdprhost.calibration.config_input import read_toml, validation_problems

    if config is None:
        source, data = f"(sample {SAMPLE})", tomllib.loads(sample_text())
    else:
        source, data = config, read_toml(config)
    camera = data.get("camera")
    if not isinstance(camera, dict):
        raise InputError("no [camera] section with board tables", source=source)
    models: dict[str, type[BoardConfig]] = {
        "reference": ReferenceBoardConfig,
        "effector": EffectorBoardConfig,
        "calibration": BoardConfig,
    }
    out: list[BoardToPrint] = []
    for name in which or BOARD_NAMES:
        key = f"{name}_board"
        table = camera.get(key)
        if table is None:
            if which:
                raise InputError(f"no [camera.{key}] table", source=source)
            continue
        try:
            model = models[name].model_validate(table)
        except ValidationError as exc:
            raise InputError(
                "invalid board", source=source, problems=validation_problems(exc, f"camera.{key}")
            ) from None
        out.append(BoardToPrint(name, model.board(), model.model_dump()))
    if not out:
        raise InputError("no [camera.*_board] table to print", source=source)
    _check_disjoint(out, source)
    return out


def _check_disjoint(boards: list[BoardToPrint], source: str) -> None:
    """All boards may be in one picture: their marker ids must not collide."""
    for i, a in enumerate(boards):
        for b in boards[i + 1 :]:
            if a.board.dictionary != b.board.dictionary:
                continue
            shared = set(a.board.marker_ids.tolist()) & set(b.board.marker_ids.tolist())
            if shared:
                raise InputError(
                    f"the {a.name} and {b.name} boards share marker ids "
                    f"({min(shared)}...{max(shared)}): give them disjoint first_marker_id",
                    source=source,
                )


def run_boards(args: argparse.Namespace) -> int:
    if args.show_sample:
        print(sample_text(), end="")
        return 0
    if not args.out:
        raise InputError("--out DIR is needed (the folder to write the sheets to)")
    from cdprhost.calibration.camera.printable import PAPERS, config_block, sheet_layout

    boards = load_boards(args.config, args.which)
    paper = PAPERS[args.paper]
    layouts = []
    for item in boards:
        try:
            layouts.append(sheet_layout(item.board, paper))
        except ValueError as exc:  # DoesNotFit, or squares too small
            raise InputError(f"the {item.name} board: {exc}") from None
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError("is not a folder", source=str(out))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot make the folder: {exc.strerror}", source=str(out)) from None
    written: list[str] = []
    try:
        for item, layout in zip(boards, layouts):
            stem = out / f"{item.name}-board-{args.paper}"
            _write(stem.with_suffix(".pdf"), draw_sheet(item, layout, "pdf"))
            written.append(f"{stem}.pdf")
            if args.png_dpi:
                _write(stem.with_suffix(".png"), draw_sheet(item, layout, "png", args.png_dpi))
                written.append(f"{stem}.png")
        block = config_block({f"{b.name}_board": b.table for b in boards})
        write_text_atomic(out / CONFIG_FILE, block)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror}", source=exc.filename or str(out)) from None
    for item, layout in zip(boards, layouts):
        w, h = item.board.size_mm
        page = f"{layout.paper.name} {'landscape' if layout.landscape else 'portrait'}"
        print(
            f"{item.name} board: {w:g} x {h:g} mm on {page}, scale bar {layout.scale_bar_mm:g} mm"
        )
    for path in written:
        print(f"  {path}")
    print(f"the tables to paste into session.toml's [camera]: {out / CONFIG_FILE}\n")
    print(block, end="")
    return 0


def _write(path: Path, data: bytes) -> None:
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def draw_sheet(item: BoardToPrint, layout: SheetLayout, fmt: str, dpi: int = 300) -> bytes:
    """One sheet as PDF or PNG bytes: the page at its paper size, the board image placed
    at its exact extent, the title and the scale bar."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    from cdprhost.calibration.camera.printable import (
        MM_PER_INCH,
        scale_bar_label,
        sheet_title,
    )

    page_w, page_h = layout.page_mm
    fig = Figure(figsize=(page_w / MM_PER_INCH, page_h / MM_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0, page_w)
    ax.set_ylim(0, page_h)
    ax.set_axis_off()
    ax.add_patch(_board_patch(item.board, layout))
    title, how = sheet_title(item.name, item.board)
    fig.text(0.5, layout.title_xy[1] / page_h, title, ha="center", va="top", fontsize=7.5)
    fig.text(0.5, (layout.title_xy[1] - 4.5) / page_h, how, ha="center", va="top", fontsize=7)
    _draw_scale_bar(ax, layout, Rectangle)
    fig.text(
        0.5,
        layout.label_xy[1] / page_h,
        scale_bar_label(layout.scale_bar_mm),
        ha="center",
        va="top",
        fontsize=7,
    )
    buf = io.BytesIO()
    metadata = {"Creator": "cdprhost calibrate boards"}
    if fmt == "pdf":
        fig.savefig(buf, format="pdf", metadata={**metadata, "CreationDate": None})
    else:
        fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": metadata["Creator"]})
    return buf.getvalue()


def _board_patch(board: CharucoBoard, layout: SheetLayout) -> Any:
    """The board's ink as one compound path of rectangles, all drawn the same way round
    (filled as their union: no seams where two touch)."""
    import numpy as np
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    from cdprhost.calibration.camera.printable import board_rectangles

    r = board_rectangles(board)
    b = layout.board
    x0 = b.x + r[:, 0]
    y1 = b.y + b.height - r[:, 1]  # the board frame's y runs down the page
    x1, y0 = x0 + r[:, 2], y1 - r[:, 3]
    corners = np.stack([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], axis=0)
    vertices = corners.transpose(2, 0, 1).reshape(-1, 2)  # (n * 5, 2), rectangle by rectangle
    codes = np.tile(
        [MplPath.MOVETO, MplPath.LINETO, MplPath.LINETO, MplPath.LINETO, MplPath.CLOSEPOLY],
        len(r),
    )
    # snap=False: matplotlib would round straight edges to its device grid (a PDF's is
    # 1/72 inch), moving them by up to 0.18 mm
    return PathPatch(
        MplPath(vertices, codes), facecolor="black", edgecolor="none", lw=0, snap=False
    )


def _draw_scale_bar(ax: Any, layout: SheetLayout, rectangle: Any) -> None:
    """A bar of whole centimetres, alternately black and white, its outer edges exactly
    ``scale_bar_mm`` apart (edges drawn inside the bar, so ink never widens it)."""
    bar = layout.scale_bar
    n_cm = round(bar.width / 10)
    for i in range(n_cm):
        fill = "black" if i % 2 == 0 else "white"
        ax.add_patch(
            rectangle((bar.x + 10 * i, bar.y), 10, bar.height, color=fill, lw=0, snap=False)
        )
    thin = 0.15  # mm: the white centimetres' outline, inside the bar
    for y in (bar.y, bar.y + bar.height - thin):
        ax.add_patch(rectangle((bar.x, y), bar.width, thin, color="black", lw=0, snap=False))
    for x in (bar.x, bar.x + bar.width - thin):  # end ticks reaching below the bar
        ax.add_patch(
            rectangle((x, bar.y - 1.5), thin, bar.height + 1.5, color="black", lw=0, snap=False)
        )
