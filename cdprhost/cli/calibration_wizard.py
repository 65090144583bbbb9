"""`cdprhost calibrate wizard`: plan the poses, move to each, take its measurement (motion
capture or camera pictures), identify, verify on the check poses and write the calibrated
profile."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from cdprhost.calibration import report
from cdprhost.calibration.identification import calibrated_profile
from cdprhost.cli.json_report import write_json
from cdprhost.cli.profile_arg import load_model
from cdprhost.errors import InputError, JobFailed
from cdprhost.profile import save_profile

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from cdprhost.calibration.identification import Identification
    from cdprhost.calibration.mocap.takes import MocapConfig
    from cdprhost.kinematics import MachineModel


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
    from cdprhost.calibration.session import mocap_for_session
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


def refuse_unless_written(result: Identification, forced: bool, verdict: str) -> None:
    """Raise JobFailed naming ``result``'s problems unless it passed or ``--force`` writes
    it anyway (``verdict``: what happened to the calibration, for the message)."""
    if result.ok or forced:
        return
    raise JobFailed(
        f"calibration {verdict}; no profile written"
        + (" (--force writes it anyway)" if result.solved else "")
        + ":\n"
        + "\n".join(f"  - {p}" for p in result.problems())
    )


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
        link = open_link(args.port, args.baud or profile.serial.baud)
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
                camera.candidates(takes, model, args.poses + args.check_poses, log)
                if camera
                else None
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
    refuse_unless_written(result, forced, "failed")
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
