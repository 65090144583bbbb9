"""`cdprhost calibrate plan | identify | camera | boards | wizard | demo`: kinematic calibration from
motion capture or one camera (`camera`: :mod:`cdprhost.cli.camera_calibration`; `boards`:
printable boards, :mod:`cdprhost.cli.board_printing`; `wizard`:
:mod:`cdprhost.cli.calibration_wizard`; `demo`: a session folder from the simulated
world, to try the others)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cdprhost.calibration import plan_files, planning, report
from cdprhost.calibration.identification import calibrated_profile
from cdprhost.calibration.session_identification import identify_session
from cdprhost.calibration.verification import DEFAULT_ALPHA
from cdprhost.cli.calibration_wizard import refuse_unless_written, run_wizard
from cdprhost.cli.json_report import write_json
from cdprhost.cli.numbers import bounded_float, bounded_int
from cdprhost.cli.options import add_device_arguments, output_file, output_folder
from cdprhost.cli.profile_arg import add_profile_argument, load_model
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.profile import save_profile

if TYPE_CHECKING:  # pragma: no cover
    pass


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    cal = sub.add_parser(
        "calibrate", help="kinematic calibration: plan poses, identify parameters, guided wizard"
    )
    cal_sub = cal.add_subparsers(dest="calibrate_command", metavar="STEP", required=True)

    plan = cal_sub.add_parser("plan", help="plan measurement poses over the whole workspace")
    add_profile_argument(plan)
    plan.add_argument(
        "--poses", type=_at_least_4, default=4, metavar="N", help="fit poses (>= 4; default 4)"
    )
    plan.add_argument(
        "--check-poses",
        type=_non_negative,
        default=3,
        metavar="M",
        help="check poses that verify the fit poses (default 3)",
    )
    plan.add_argument(
        "--criterion",
        choices=planning.CRITERIA,
        default="D",
        help="D-optimal (default), I (mean prediction variance) or an observability index O1-O5",
    )
    plan.add_argument(
        "--restarts",
        type=_non_negative,
        default=8,
        help="random restarts of the exchange (default 8)",
    )
    plan.add_argument("--seed", type=bounded_int(0, 2**32 - 1), default=0)
    plan.add_argument(
        "--out",
        type=output_file,
        required=True,
        metavar="poses.csv",
        help="poses in visiting order with role and approach",
    )
    plan.add_argument("--json", type=output_file, metavar="R", help="machine-readable report")
    plan.set_defaults(func=run_plan)

    ident = cal_sub.add_parser("identify", help="identify the 12 parameters from a session folder")
    ident.add_argument(
        "session", metavar="SESSION", help="session folder (session.toml, poses.csv, takes/)"
    )
    add_profile_argument(ident)
    ident.add_argument(
        "--out",
        type=output_file,
        required=True,
        metavar="calibrated.toml",
        help="calibrated profile",
    )
    ident.add_argument("--json", type=output_file, metavar="R", help="machine-readable report")
    ident.add_argument(
        "--noise-floor",
        type=bounded_float(0.0, 10.0),
        default=None,
        metavar="MM",
        help="mocap noise per coordinate that averaging cannot remove, added to each take's "
        "standard error (default: noise_mm of session.toml, else none)",
    )
    ident.add_argument(
        "--max-workspace-error",
        type=_positive_mm,
        default=1.0,
        metavar="MM",
        help="refuse when the predicted workspace error exceeds this (default 1 mm)",
    )
    ident.add_argument(
        "--force",
        action="store_true",
        help="write the profile even when the trust gate or the verification refuses it "
        "(the report still says ok: false)",
    )
    _add_verification_arguments(ident)
    ident.set_defaults(func=run_identify)

    from cdprhost.cli import board_printing, camera_calibration

    camera_calibration.register(cal_sub)
    board_printing.register(cal_sub)

    wiz = cal_sub.add_parser(
        "wizard", help="guided calibration: move to planned poses, record takes, identify"
    )
    add_profile_argument(wiz)
    add_device_arguments(wiz)
    wiz.add_argument(
        "--session",
        metavar="DIR",
        help="session folder; an existing one is resumed (default: ./calibration-<date>)",
    )
    wiz.add_argument(
        "--poses",
        type=_at_least_4,
        default=4,
        metavar="N",
        help="fit poses, planned D-optimally over the whole workspace (default 4, the minimum)",
    )
    wiz.add_argument(
        "--check-poses",
        type=_non_negative,
        default=3,
        metavar="M",
        help="check poses that verify the fit poses before the refit on all (default 3)",
    )
    _add_verification_arguments(wiz)
    wiz.add_argument(
        "--force",
        action="store_true",
        help="write the profile even when the trust gate or the verification refuses it",
    )
    wiz.add_argument("--criterion", choices=planning.CRITERIA, default="D")
    src = wiz.add_mutually_exclusive_group()
    src.add_argument("--watch", metavar="DIR", help="wait for each new take file to appear in DIR")
    src.add_argument(
        "--takes-from",
        metavar="DIR",
        help="takes recorded beforehand: the file ending in the pose number",
    )
    wiz.add_argument(
        "--mocap-config",
        metavar="TOML",
        help="a session.toml-like file whose [mocap] table names the "
        "markers (needed for a new session with real motion capture)",
    )
    camera_calibration.add_wizard_arguments(wiz)
    wiz.add_argument(
        "--sim-truth", metavar="PROFILE", help="embedded device: the hidden true machine"
    )
    wiz.add_argument(
        "--sim-mocap-dir",
        metavar="DIR",
        help="embedded device: folder of its virtual motion capture",
    )
    wiz.add_argument(
        "--speedup",
        type=bounded_float(0.0, 1e6),
        help="embedded device: pace virtual time at X times real time",
    )
    wiz.add_argument(
        "--feed",
        type=bounded_float(0.0, 1000.0),
        default=40.0,
        metavar="MM_S",
        help="travel speed between poses (default 40)",
    )
    wiz.add_argument(
        "--settle",
        type=bounded_float(0.0, 600.0, lo_open=False),
        default=0.5,
        metavar="S",
        help="rest before a take (default 0.5 s)",
    )
    wiz.add_argument(
        "--take-timeout",
        type=bounded_float(0.0, 86400.0),
        default=600.0,
        metavar="S",
        help="wait for a take at most S seconds",
    )
    wiz.add_argument(
        "--noise-floor",
        type=bounded_float(0.0, 10.0),
        default=None,
        metavar="MM",
        help="mocap noise per coordinate that averaging cannot remove (default: none)",
    )
    wiz.add_argument(
        "--out",
        type=output_file,
        metavar="calibrated.toml",
        help="also write the calibrated profile here",
    )
    wiz.add_argument("--json", type=output_file, metavar="R", help="machine-readable report")
    wiz.set_defaults(func=run_wizard)

    demo = cal_sub.add_parser(
        "demo",
        help="write a session folder measured on a hidden simulated machine, to try identify, "
        "diagnose and the wizard without a machine",
    )
    add_profile_argument(demo)
    demo.add_argument(
        "--out",
        type=output_folder,
        required=True,
        metavar="DIR",
        help="the session folder to write",
    )
    demo.add_argument(
        "--effect",
        default="cable_elasticity",
        help="effect the hidden machine has and the profile lacks, or 'none' "
        "(default cable_elasticity)",
    )
    demo.add_argument(
        "--poses", type=_at_least_4, default=12, metavar="N", help="fit poses (default 12)"
    )
    demo.add_argument(
        "--check-poses", type=_non_negative, default=3, metavar="M", help="check poses (default 3)"
    )
    demo.add_argument("--seed", type=bounded_int(0, 2**32 - 1), default=1)
    demo.set_defaults(func=run_demo)


def _add_verification_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--no-refine",
        dest="refine",
        action="store_false",
        help="keep the fit on the fit poses only (default: once the check poses agree with "
        "its prediction, refit on fit + check poses)",
    )
    parser.add_argument(
        "--false-alarm",
        type=bounded_float(1e-9, 0.5),
        default=DEFAULT_ALPHA,
        metavar="P",
        help="false-alarm rate of the check-pose test (default 0.01)",
    )


MAX_POSES = 1000  # planning and identification cost grows with the poses: a typo stops here


def _at_least_4(text: str) -> int:
    n = _whole(text)
    if n < 4:
        raise argparse.ArgumentTypeError("at least 4 poses are needed to identify 12 parameters")
    if n > MAX_POSES:
        raise argparse.ArgumentTypeError(f"{n} poses: at most {MAX_POSES}")
    return n


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _positive_mm(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v > 0 and v < float("inf")):
        raise argparse.ArgumentTypeError("must be a positive number of millimetres")
    return v


def _non_negative(text: str) -> int:
    n = _whole(text)
    if n < 0:
        raise argparse.ArgumentTypeError("must be >= 0")
    if n > MAX_POSES:
        raise argparse.ArgumentTypeError(f"{n}: at most {MAX_POSES}")
    return n


def run_plan(args: argparse.Namespace) -> int:
    _, model = load_model(args.profile)
    try:
        plan = planning.plan_poses(
            model,
            args.poses,
            n_check=args.check_poses,
            criterion=args.criterion,
            restarts=args.restarts,
            seed=args.seed,
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
    write_text_atomic(args.out, plan_files.plan_csv(plan))
    write_json(args.json, planning_json(plan))
    print(report.plan_text(plan))
    return 0


def planning_json(plan: planning.PosePlan) -> dict[str, Any]:
    return {
        "poses": plan.poses.tolist(),
        "roles": list(plan.roles),
        "approach": plan.approach.tolist(),
        "directions": plan.directions.astype(int).tolist(),
        "criterion": plan.criterion,
        "indices": plan.indices,
        "table1_indices": plan.table1_indices,
        "candidates": plan.n_candidates,
        "travel_mm": plan.travel_mm,
    }


def run_identify(args: argparse.Namespace) -> int:
    from cdprhost.calibration.trust import TrustLimits

    profile, model = load_model(args.profile)
    limits = TrustLimits(max_workspace_mm=args.max_workspace_error)
    result = identify_session(
        args.session,
        model,
        noise_floor_mm=args.noise_floor,
        limits=limits,
        refine=args.refine,
        alpha=args.false_alarm,
    )
    forced = bool(args.force) and result.solved and not result.ok
    write_json(args.json, {**result.to_json(), "forced": forced})
    print(report.identification_text(result))
    refuse_unless_written(result, forced, "refused")
    calibrated = calibrated_profile(profile, result, session=str(Path(args.session).resolve()))
    save_profile(calibrated, args.out)
    if forced:
        print(
            "\nWARNING: the trust gate refused this result; written because of --force",
            file=sys.stderr,
        )
    print(f"\ncalibrated profile written to {args.out}", file=sys.stderr)
    return 0


def run_demo(args: argparse.Namespace) -> int:
    from cdprhost.sim.demo_session import truth_profile, write_demo_session

    profile, _ = load_model(args.profile)
    effect = None if args.effect == "none" else args.effect
    if effect is not None and effect not in _effect_names():
        raise InputError(
            f"--effect {args.effect}: unknown (known: {', '.join(_effect_names())}, none)"
        )
    try:
        demo = write_demo_session(
            args.out,
            profile,
            effect=effect,
            n_fit=args.poses,
            n_check=args.check_poses,
            seed=args.seed,
        )
    except FileExistsError as exc:
        raise InputError(str(exc)) from None
    truth_path = demo.directory / "hidden-truth.toml"
    save_profile(truth_profile(profile, demo.truth), truth_path)
    fit = sum(1 for r in demo.roles if r == "fit")
    print(
        f"{demo.directory}: a calibration session of a hidden machine (geometry off profile "
        f"{profile.name} by up to 2 mm, {effect or 'no effect'} added): {fit} fit + "
        f"{len(demo.roles) - fit} check poses, Motive CSV takes of a realistic virtual "
        f"motion capture\n"
        f"  the hidden machine (for --sim-truth, and to compare; do not peek): {truth_path}\n"
        f"  next: cdprhost calibrate identify {demo.directory} --profile {args.profile} "
        f"--out calibrated.toml"
    )
    return 0


def _effect_names() -> list[str]:
    from cdprhost.effects.registry import CATALOGUE

    return list(CATALOGUE)
