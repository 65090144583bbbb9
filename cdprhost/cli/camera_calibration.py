"""`cdprhost calibrate camera VIEWS --board ... --out camera.toml`: a camera's intrinsics from
pictures of a ChArUco board, with the reprojection error, each parameter's uncertainty
and a coverage check that refuses views that cannot pin the parameters down (exit 1,
naming the reason and which views to add). ``VIEWS`` is a folder of pictures, a video,
or a camera session folder (its ``calibration_views`` and ``[camera.calibration_board]``).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cdprhost.errors import InputError, JobFailed

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.calibration.camera.boards import CharucoBoard
    from cdprhost.calibration.camera.intrinsics import IntrinsicsResult

BOARD_HELP = (
    "the board: SXxSY,SQUARE_MM,MARKER_MM[,DICTIONARY[,FIRST_MARKER_ID]] "
    "(e.g. 9x6,25,18,DICT_5X5_250,150), or a TOML file with the board's table "
    "(a session.toml: its [camera.calibration_board])"
)


def register(cal_sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    cam = cal_sub.add_parser(
        "camera", help="camera intrinsics from pictures of a ChArUco board (camera.toml)"
    )
    cam.add_argument(
        "views",
        metavar="VIEWS",
        help="folder of pictures, a video, or a camera session folder (its calibration_views)",
    )
    cam.add_argument("--board", metavar="SPEC", help=BOARD_HELP)
    cam.add_argument("--out", required=True, metavar="camera.toml", help="intrinsics to write")
    cam.add_argument("--json", metavar="R", help="machine-readable report")
    cam.add_argument(
        "--force",
        action="store_true",
        help="write camera.toml even when the coverage check refuses the views",
    )
    cam.set_defaults(func=run_camera)


def parse_board(text: str) -> CharucoBoard:
    """A board from ``--board``: the compact spec, or a TOML file's board table."""
    from cdprhost.calibration.camera.boards import CharucoBoard

    path = Path(text)
    if path.suffix.lower() == ".toml" or path.is_file():
        return _board_from_toml(path)
    m = re.fullmatch(
        r"\s*(\d+)\s*[xX]\s*(\d+)\s*,([^,]+),([^,]+)(?:,([A-Za-z0-9_]+))?(?:,(\d+))?\s*", text
    )
    if not m:
        raise InputError(f"--board: cannot read {text!r}; expected {BOARD_HELP}")
    try:
        return CharucoBoard(
            (int(m[1]), int(m[2])),
            float(m[3]),
            float(m[4]),
            m[5] or "DICT_5X5_250",
            int(m[6] or 0),
        )
    except ValueError as exc:
        raise InputError(f"--board {text!r}: {exc}") from None


def _board_from_toml(path: Path) -> CharucoBoard:
    from pydantic import ValidationError

    from cdprhost.calibration.camera_config import BoardConfig
    from cdprhost.calibration.session import read_toml, validation_problems

    data = read_toml(path)
    table: Any = data.get("camera", {}).get("calibration_board") if "camera" in data else data
    where = "camera.calibration_board" if "camera" in data else ""
    if table is None:
        raise InputError("no [camera.calibration_board] table", source=str(path))
    try:
        return BoardConfig.model_validate(table).board()
    except ValidationError as exc:
        raise InputError(
            "invalid board", source=str(path), problems=validation_problems(exc, where)
        ) from None


def _views_and_board(args: argparse.Namespace) -> tuple[Path, CharucoBoard]:
    from cdprhost.calibration.session import SESSION_FILE, contained_path, load_session_config

    views = Path(args.views)
    if (views / SESSION_FILE).is_file():
        camera = load_session_config(views / SESSION_FILE).camera
        if camera is None or camera.calibration_views is None:
            raise InputError(
                "this session has no calibration_views in [camera]",
                source=str(views / SESSION_FILE),
            )
        where = contained_path(views, camera.calibration_views)
        if isinstance(where, str):
            raise InputError(
                f"[camera] calibration_views: {where}", source=str(views / SESSION_FILE)
            )
        assert camera.calibration_board is not None  # the model guarantees it
        board = parse_board(args.board) if args.board else camera.calibration_board.board()
        return where, board
    if not args.board:
        raise InputError("--board is needed (the views are not a camera session folder)")
    if not views.exists():
        raise InputError("no such folder or video", source=str(views))
    return views, parse_board(args.board)


def result_json(result: IntrinsicsResult, names: tuple[str, ...]) -> dict[str, Any]:
    c = result.coverage
    return {
        "ok": result.ok,
        "rms_reprojection_px": result.rms_px,
        "intrinsics": result.intrinsics.to_json(),
        "coverage": {
            "ok": c.ok,
            "reason": c.reason,
            "advice": c.advice,
            "cell_fraction": c.cell_fraction,
            "corner_cells": c.corner_cells,
            "max_tilt_deg": c.max_tilt_deg,
            "tilt_axes": c.tilt_axes,
        },
        "views": len(names),
        "views_used": [names[i] for i in result.views_used],
        "views_dropped": [{"view": names[i], "reason": why} for i, why in result.views_dropped],
        "problems": result.problems,
    }


def result_text(result: IntrinsicsResult, names: tuple[str, ...]) -> str:
    from cdprhost.calibration.camera.intrinsics import PARAMETER_NAMES

    intr = result.intrinsics
    w, h = intr.image_size
    lines = [
        f"camera intrinsics from {len(result.views_used)} of {len(names)} views ({w}x{h} px)",
        f"reprojection error RMS {result.rms_px:.3f} px",
    ]
    for name, value, std in zip(PARAMETER_NAMES, intr.vector, intr.std):
        unc = f" +- {std:.4g}" if math.isfinite(std) else ""
        lines.append(f"  {name:>3} = {value:.6g}{unc}")
    c = result.coverage
    lines.append(
        f"coverage: corners reach {c.cell_fraction:.0%} of the image's cells, "
        f"{c.corner_cells}/4 of its corners; tilt up to {c.max_tilt_deg:.0f} deg "
        f"about {c.tilt_axes} axis(es)"
    )
    lines += [f"  view {names[i]} not used: {why}" for i, why in result.views_dropped]
    return "\n".join(lines)


def run_camera(args: argparse.Namespace) -> int:
    from cdprhost.calibration.camera_config import intrinsics_toml
    from cdprhost.calibration.camera_takes import calibrate_from_views
    from cdprhost.cli.commands.calibrate import write_json
    from cdprhost.fileio.atomic import write_text_atomic

    views, board = _views_and_board(args)
    result, names = calibrate_from_views(views, board)
    forced = bool(args.force) and not result.ok
    write_json(args.json, {**result_json(result, names), "forced": forced})
    print(result_text(result, names))
    if not result.ok and not forced:
        raise JobFailed(
            "camera calibration refused; no camera.toml written (--force writes it anyway):\n"
            + "\n".join(f"  - {p}" for p in result.problems)
        )
    write_text_atomic(args.out, intrinsics_toml(result.intrinsics))
    if forced:
        print(
            "\nWARNING: the coverage check refused these views; written because of --force",
            file=sys.stderr,
        )
    print(f"\nintrinsics written to {args.out}", file=sys.stderr)
    return 0
