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

from cdprhost.calibration.camera.wizard_camera import (
    WizardCamera,
    picture_size,
    picture_size_problem,
)
from cdprhost.cli.numbers import bounded_int
from cdprhost.cli.options import output_file, output_folder
from cdprhost.errors import InputError, JobFailed

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.calibration.camera.boards import CharucoBoard
    from cdprhost.calibration.camera.intrinsics import IntrinsicsResult

BOARD_HELP = (
    "the board: SXxSY,SQUARE_MM,MARKER_MM[,DICTIONARY[,FIRST_MARKER_ID]][,legacy] "
    "(e.g. 9x6,25,18,DICT_5X5_250,150; legacy: OpenCV's layout before 4.6), or a TOML file with the board's table "
    "(a session.toml: its [camera.calibration_board])"
)


def register(cal_sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    cam = cal_sub.add_parser(
        "camera", help="camera intrinsics from pictures of a ChArUco board (camera.toml)"
    )
    cam.add_argument(
        "views",
        metavar="VIEWS",
        nargs="?",
        help="folder of pictures, a video, or a camera session folder (its calibration_views)",
    )
    cam.add_argument(
        "--camera",
        metavar="SOURCE",
        help="take the views live instead: a device index, a video or a URL that OpenCV "
        "opens, or 'sim' (a simulated camera and board); move the board between views",
    )
    cam.add_argument(
        "--views",
        dest="n_views",
        type=bounded_int(3, 500),
        default=20,
        metavar="N",
        help="live: views to take (default 20)",
    )
    cam.add_argument(
        "--save-views", type=output_folder, metavar="DIR", help="live: also store the views taken"
    )
    cam.add_argument(
        "--sim-camera",
        type=sim_camera_size,
        default="1920x1080",
        metavar="WxH",
        help="--camera sim: picture size (320x240 to 3840x2160; default 1920x1080)",
    )
    cam.add_argument("--board", metavar="SPEC", help=BOARD_HELP)
    cam.add_argument(
        "--out", type=output_file, required=True, metavar="camera.toml", help="intrinsics to write"
    )
    cam.add_argument("--json", type=output_file, metavar="R", help="machine-readable report")
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
    legacy = re.search(r",\s*legacy\s*$", text, re.IGNORECASE)
    spec = text[: legacy.start()] if legacy else text
    m = re.fullmatch(
        r"\s*(\d+)\s*[xX]\s*(\d+)\s*,([^,]+),([^,]+)(?:,([A-Za-z0-9_]+))?(?:,(\d+))?\s*", spec
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
            legacy_pattern=bool(legacy),
        )
    except ValueError as exc:
        raise InputError(f"--board {text!r}: {exc}") from None


def _board_from_toml(path: Path) -> CharucoBoard:
    from pydantic import ValidationError

    from cdprhost.calibration.camera.config import BoardConfig
    from cdprhost.calibration.config_input import read_toml, validation_problems

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
    from cdprhost.calibration.config_input import contained_path
    from cdprhost.calibration.session import SESSION_FILE, load_session_config

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


def _calibrate_live(args: argparse.Namespace) -> tuple[IntrinsicsResult, tuple[str, ...]]:
    import cv2

    from cdprhost.calibration.camera.capture import collect_views, open_capture
    from cdprhost.calibration.camera.intrinsics import calibrate_intrinsics

    if not args.board and args.camera.strip().lower() != "sim":
        raise InputError("--board is needed with --camera")
    if args.camera.strip().lower() == "sim":
        from cdprhost.sim.camera.device import ViewsCapture
        from cdprhost.sim.camera.scene import CALIBRATION_BOARD

        capture: Any = ViewsCapture(sim_rig(args.sim_camera), args.n_views + 8)
        board = parse_board(args.board) if args.board else CALIBRATION_BOARD
    else:
        capture = open_capture(args.camera)
        board = parse_board(args.board)
    try:
        print(
            f"move the board to a new place and tilt for each of {args.n_views} views", flush=True
        )
        detections, images = collect_views(
            capture, board, args.n_views, log=lambda m: print(m, flush=True)
        )
    finally:
        capture.release()
    if len(images) < 3:
        raise JobFailed(
            f"the board was found in only {len(images)} distinct view(s); 3 or more needed"
        )
    names = tuple(f"view_{i:02d}.png" for i in range(1, len(images) + 1))
    if args.save_views:
        folder = Path(args.save_views)
        folder.mkdir(parents=True, exist_ok=True)
        for name, image in zip(names, images):
            cv2.imwrite(str(folder / name), image)
    h, w = images[0].shape[:2]
    return calibrate_intrinsics(detections, board, (w, h)), names


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
            "region": c.region,
            "region_sd_px": c.region_sd_px if math.isfinite(c.region_sd_px) else None,
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
        + (
            f"; lens known to {c.region_sd_px:.3f} px in {c.region}"
            if math.isfinite(c.region_sd_px)
            else ""
        )
    )
    lines += [f"  view {names[i]} not used: {why}" for i, why in result.views_dropped]
    return "\n".join(lines)


def run_camera(args: argparse.Namespace) -> int:
    from cdprhost.calibration.camera.config import intrinsics_toml
    from cdprhost.calibration.camera.takes import calibrate_from_views
    from cdprhost.cli.json_report import write_json
    from cdprhost.fileio.atomic import write_text_atomic

    if args.camera:
        result, names = _calibrate_live(args)
    else:
        if not args.views:
            raise InputError("give VIEWS (a folder, a video or a session) or --camera")
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


# ---------------------------------------------------------------- the wizard with a camera
def add_wizard_arguments(wiz: argparse.ArgumentParser) -> None:
    wiz.add_argument(
        "--camera",
        metavar="SOURCE",
        help="take pictures with a camera instead of motion capture: a device index (0), a "
        "video file or a URL that OpenCV opens, or 'sim' (the simulated camera beside the "
        "embedded simulated device)",
    )
    wiz.add_argument(
        "--camera-config",
        metavar="TOML",
        help="a session.toml-like file whose [camera] table describes the boards "
        "(needed for a new session with a real camera)",
    )
    wiz.add_argument(
        "--camera-intrinsics",
        metavar="camera.toml",
        help="the camera's intrinsics (from `cdprhost calibrate camera`)",
    )
    wiz.add_argument(
        "--frames",
        type=bounded_int(1, 1000),
        default=5,
        metavar="N",
        help="pictures per take (1-1000; default 5)",
    )
    wiz.add_argument(
        "--sim-camera",
        type=sim_camera_size,
        default="1920x1080",
        metavar="WxH",
        help="simulated camera: picture size (320x240 to 3840x2160; default 1920x1080; smaller "
        "sizes get bigger boards)",
    )


def sim_camera_size(text: str) -> str:
    """An argparse ``type`` for ``--sim-camera WxH`` (bounded before anything is drawn)."""
    problem = picture_size_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return text


def sim_rig(size_text: str) -> Any:
    from cdprhost.sim.camera.scene import rig_for_size

    problem = picture_size_problem(size_text)
    size = picture_size(size_text)
    if problem or size is None:
        raise InputError(f"--sim-camera: {problem}")
    return rig_for_size(size)


def camera_for_wizard(args: argparse.Namespace, session: Path, model: Any) -> WizardCamera:
    """The capture, the [camera] configuration and the intrinsics of `wizard --camera`."""
    from cdprhost.calibration.camera.config import load_camera_config, load_intrinsics
    from cdprhost.calibration.camera.takes import session_intrinsics
    from cdprhost.calibration.session import SESSION_FILE, load_session_config

    sim = args.camera.strip().lower() == "sim"
    if sim and args.port:
        raise InputError("--camera sim watches the embedded simulated device; drop --port")
    if not sim and (args.sim_truth or args.sim_mocap_dir):
        raise InputError("--sim-truth/--sim-mocap-dir need the simulated camera (--camera sim)")
    observer: Any = None
    capture: Any = None
    rig: Any = None
    if sim:
        from cdprhost.kinematics import MachineModel
        from cdprhost.profile import load_profile
        from cdprhost.sim.camera.device import VirtualCamera

        rig = sim_rig(args.sim_camera)
        truth = MachineModel.from_profile(load_profile(args.sim_truth)) if args.sim_truth else model
        capture = observer = VirtualCamera(truth, rig)
    else:
        from cdprhost.calibration.camera.capture import open_capture

        capture = open_capture(args.camera)
    if (session / SESSION_FILE).is_file():
        config = load_session_config(session / SESSION_FILE).camera
        if config is None:
            raise InputError(
                "this session measures with motion capture, not a camera", source=str(session)
            )
    elif args.camera_config:
        config = load_camera_config(args.camera_config)
    elif rig is not None:
        from cdprhost.sim.camera.session import camera_config

        config = camera_config(rig)
    else:
        raise InputError(
            "a new camera session needs --camera-config (a TOML file with the [camera] table "
            "of session.toml: the reference and effector boards)"
        )
    if args.camera_intrinsics:
        intrinsics = load_intrinsics(args.camera_intrinsics)
    elif (session / SESSION_FILE).is_file():
        intrinsics = session_intrinsics(session, config)[0]
    elif rig is not None:
        from cdprhost.sim.camera.session import calibrated_intrinsics

        print("simulated camera: calibrating its intrinsics from rendered views", flush=True)
        result = calibrated_intrinsics(rig)
        if not result.ok:  # pragma: no cover - the rendered views cover the image
            raise JobFailed("; ".join(result.problems))
        intrinsics = result.intrinsics
    else:
        raise InputError(
            "a camera needs its intrinsics: give --camera-intrinsics camera.toml "
            "(from `cdprhost calibrate camera`)"
        )
    return WizardCamera(capture, config, intrinsics, observer)
