"""`cdprhost calibrate plan | identify | camera | wizard | demo`: kinematic calibration from
motion capture or one camera (`camera`: :mod:`cdprhost.cli.camera_calibration`; `demo`: a session
folder from the simulated world, to try the others)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cdprhost.calibration import plan_files, planning, report
from cdprhost.calibration.identification import calibrated_profile, identify_session
from cdprhost.calibration.verification import DEFAULT_ALPHA
from cdprhost.cli.numbers import bounded_float
from cdprhost.cli.profile_arg import add_profile_argument, load_model
from cdprhost.errors import InputError, JobFailed
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.jsonsafe import dumps
from cdprhost.profile import save_profile

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from cdprhost.calibration.takes import MocapConfig
    from cdprhost.kinematics import MachineModel


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
    plan.add_argument("--seed", type=int, default=0)
    plan.add_argument(
        "--out",
        required=True,
        metavar="poses.csv",
        help="poses in visiting order with role and approach",
    )
    plan.add_argument("--json", metavar="R", help="machine-readable report")
    plan.set_defaults(func=run_plan)

    ident = cal_sub.add_parser("identify", help="identify the 12 parameters from a session folder")
    ident.add_argument(
        "session", metavar="SESSION", help="session folder (session.toml, poses.csv, takes/)"
    )
    add_profile_argument(ident)
    ident.add_argument("--out", required=True, metavar="calibrated.toml", help="calibrated profile")
    ident.add_argument("--json", metavar="R", help="machine-readable report")
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

    from cdprhost.cli import camera_calibration

    camera_calibration.register(cal_sub)

    wiz = cal_sub.add_parser(
        "wizard", help="guided calibration: move to planned poses, record takes, identify"
    )
    add_profile_argument(wiz)
    wiz.add_argument(
        "--port",
        metavar="DEV",
        help="device path or pyserial URL (default: the embedded simulated device)",
    )
    wiz.add_argument("--baud", type=int, default=250000)
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
        "--speedup", type=float, help="embedded device: pace virtual time at X times real time"
    )
    wiz.add_argument(
        "--feed",
        type=float,
        default=40.0,
        metavar="MM_S",
        help="travel speed between poses (default 40)",
    )
    wiz.add_argument(
        "--settle", type=float, default=0.5, metavar="S", help="rest before a take (default 0.5 s)"
    )
    wiz.add_argument(
        "--take-timeout",
        type=float,
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
        "--out", metavar="calibrated.toml", help="also write the calibrated profile here"
    )
    wiz.add_argument("--json", metavar="R", help="machine-readable report")
    wiz.set_defaults(func=run_wizard)

    demo = cal_sub.add_parser(
        "demo",
        help="write a session folder measured on a hidden simulated machine, to try identify, "
        "diagnose and the wizard without a machine",
    )
    add_profile_argument(demo)
    demo.add_argument("--out", required=True, metavar="DIR", help="the session folder to write")
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
    demo.add_argument("--seed", type=int, default=1)
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


def _at_least_4(text: str) -> int:
    n = int(text)
    if n < 4:
        raise argparse.ArgumentTypeError("at least 4 poses are needed to identify 12 parameters")
    return n


def _positive_mm(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v > 0 and v < float("inf")):
        raise argparse.ArgumentTypeError("must be a positive number of millimetres")
    return v


def _non_negative(text: str) -> int:
    n = int(text)
    if n < 0:
        raise argparse.ArgumentTypeError("must be >= 0")
    return n


def write_json(path: str | None, data: dict[str, Any]) -> None:
    if path:
        write_text_atomic(path, dumps(data, indent=2) + "\n")


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
    if not result.ok and not forced:
        raise JobFailed(
            "calibration refused; no profile written"
            + (" (--force writes it anyway)" if result.solved else "")
            + ":\n"
            + "\n".join(f"  - {p}" for p in result.problems())
        )
    calibrated = calibrated_profile(profile, result, session=str(Path(args.session).resolve()))
    save_profile(calibrated, args.out)
    if forced:
        print(
            "\nWARNING: the trust gate refused this result; written because of --force",
            file=sys.stderr,
        )
    print(f"\ncalibrated profile written to {args.out}", file=sys.stderr)
    return 0


class PromptTakes:
    """Asks the user, on the terminal, for the take file of each pose."""

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        where = ", ".join(f"{v:.1f}" for v in pose)
        while True:
            try:
                text = input(
                    f"pose {index + 1} at ({where}) has settled: record a take, then enter its file path: "
                )
            except EOFError:
                raise InputError("no take given (end of input)") from None
            path = Path(text.strip().strip('"').strip("'")).expanduser()
            if path.is_file():
                return path
            print(f"  not a file: {path}", file=sys.stderr)


def _mocap_for(args: argparse.Namespace, session: Path) -> MocapConfig | None:
    from cdprhost.calibration.session_setup import mocap_for_session
    from cdprhost.sim.virtual_mocap import mocap_config

    if (session / "session.toml").is_file():
        return None  # resuming: the folder's own configuration
    if not args.mocap_config and not (args.sim_mocap_dir and not args.port):
        raise InputError(
            "a new session needs --mocap-config (a TOML file with the [mocap] table of "
            "session.toml: base markers, effector markers and offset); or, on the embedded "
            "simulated device, --sim-truth PROFILE --sim-mocap-dir DIR (its virtual motion "
            "capture; `cdprhost calibrate demo` writes a truth to try)"
        )
    virtual = mocap_config().mocap if args.sim_mocap_dir and not args.port else None
    return mocap_for_session(session, args.mocap_config, virtual)


def run_wizard(args: argparse.Namespace) -> int:
    import datetime as dt

    from cdprhost.calibration import wizard
    from cdprhost.cli.camera_calibration import camera_for_wizard
    from cdprhost.link import open_link
    from cdprhost.machine import Machine
    from cdprhost.sim.embedded import open_embedded
    from cdprhost.sim.virtual_mocap import make_observer

    profile, model = load_model(args.profile)
    if args.port and (args.sim_truth or args.sim_mocap_dir):
        raise InputError(
            "--sim-truth/--sim-mocap-dir drive the embedded simulated device; drop them with --port"
        )
    if args.camera and args.sim_mocap_dir:
        raise InputError(
            "--sim-mocap-dir is the virtual motion capture's folder; with --camera the "
            "simulated camera takes the pictures: drop it"
        )
    if not args.camera and bool(args.sim_truth) != bool(args.sim_mocap_dir):
        given, missing = (
            ("--sim-truth", "--sim-mocap-dir")
            if args.sim_truth
            else ("--sim-mocap-dir", "--sim-truth")
        )
        raise InputError(
            f"{given} needs {missing} too (the virtual motion capture needs a true machine "
            "and a folder for its takes)"
        )
    if args.sim_truth and not args.port:
        _check_sim_truth(args.sim_truth, args.profile, model)
    session = Path(args.session or f"calibration-{dt.datetime.now():%Y%m%d-%H%M%S}")
    camera = camera_for_wizard(args, session, model) if args.camera else None
    mocap = None if camera else _mocap_for(args, session)
    watch = args.watch or (args.sim_mocap_dir if not args.takes_from else None)
    takes: wizard.TakeSource
    log = lambda m: print(m, flush=True)  # noqa: E731
    if camera is not None:
        takes = camera.takes(session, args.frames, log)
    elif watch:
        takes = wizard.FolderWatcher(Path(watch), timeout_s=args.take_timeout)
    elif args.takes_from:
        takes = wizard.NumberedTakes(Path(args.takes_from))
    elif sys.stdin.isatty():
        takes = PromptTakes()
    else:
        raise InputError(
            "no way to get takes: give --watch DIR or --takes-from DIR (or run on a terminal)"
        )
    if args.port:
        link = open_link(args.port, args.baud)
    else:
        observer = camera.observer if camera else make_observer(args.sim_truth, args.sim_mocap_dir)
        link = open_embedded(observer=observer, speedup=args.speedup)
        if observer is not None:
            observer.attach_record(link.device.record)
    try:
        device = Machine(link, profile, model, feed_mm_s=args.feed, settle_s=args.settle)
        options = wizard.WizardOptions(
            n_poses=args.poses,
            n_check=args.check_poses,
            criterion=args.criterion,
            noise_floor_mm=args.noise_floor,
            refine=args.refine,
            alpha=args.false_alarm,
        )
        wiz = wizard.CalibrationWizard(
            session,
            profile,
            device,
            takes,
            mocap=mocap,
            options=options,
            profile_ref=args.profile,
            log=log,
            camera=camera.config if camera else None,
            intrinsics=camera.intrinsics if camera else None,
            candidates=(
                camera.candidates(takes, model, args.poses + args.check_poses) if camera else None
            ),
        )
        outcome = wiz.run()
    except KeyboardInterrupt:
        print(
            f"\ninterrupted: everything recorded is in {session}; resume with --session {session}",
            file=sys.stderr,
        )
        raise
    finally:
        link.close()
    result = outcome.identification
    finished = outcome.state.next_action()
    if result is None:
        raise JobFailed(
            f"calibration incomplete: {getattr(finished, 'reason', '')}; session kept in {session}"
        )
    forced = bool(args.force) and result.solved and not result.ok
    calibrated, profile_path = outcome.profile, outcome.profile_path
    if forced:
        calibrated = calibrated_profile(profile, result, session=str(session.resolve()))
        profile_path = session / wizard.PROFILE_FILE
        save_profile(calibrated, profile_path)
    write_json(
        args.json,
        {
            **result.to_json(),
            "forced": forced,
            "session": str(session),
            "profile_path": str(profile_path) if profile_path else None,
        },
    )
    print(report.identification_text(result))
    if not result.ok and not forced:
        raise JobFailed(
            "calibration failed; no profile written"
            + (" (--force writes it anyway)" if result.solved else "")
            + ":\n"
            + "\n".join(f"  - {p}" for p in result.problems())
        )
    if forced:
        print("\nWARNING: calibration refused; written because of --force", file=sys.stderr)
    if args.out and calibrated is not None:
        save_profile(calibrated, args.out)
    print(
        f"\nbefore/after:\n{report.summary_text(result)}\ncalibrated profile: {args.out or profile_path}"
    )
    return 0


def _check_sim_truth(truth_ref: str, profile_ref: str, model: MachineModel) -> None:
    from cdprhost.calibration.wizard import WizardOptions
    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import load_profile
    from cdprhost.sim.demo_session import sim_truth_problem

    truth = MachineModel.from_profile(load_profile(truth_ref))
    problem = sim_truth_problem(model, truth, WizardOptions().max_offset_mm, truth_ref, profile_ref)
    if problem:
        raise InputError(problem)


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
