"""`cdprhost print FILE.gcode --profile P [--port DEV] ...`: preflight, then print.

Without ``--port`` the job runs on the embedded simulated device (accelerated).
Ctrl-C, SIGHUP and SIGTERM cancel like the operator would: the machine stops within the
motion already sent, parks, switches the heaters off and the resume point is saved; a
second signal stops it at once (emergency stop). An M600 pause asks whether to resume.
``--resume`` continues exactly where the file's last print stopped (its resume point,
kept up to date while printing); ``--resume-from-layer N`` restarts at a layer.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import json
import queue
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cdprhost.cli.numbers import bounded_float, bounded_int
from cdprhost.cli.options import (
    add_device_arguments,
    add_placement_arguments,
    existing_gcode,
    setup_from_args,
)
from cdprhost.cli.profile_arg import add_profile_argument
from cdprhost.cli.progress_view import ProgressView
from cdprhost.cli.signals import stop_signals
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.job.resume import find_resume_point, log_path_for, resume_question, resume_setup
from cdprhost.job.state import JobState, StateChanged

MAX_SPEEDUP = 100_000.0


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "print", help="print a G-code file (embedded simulated device unless --port is given)"
    )
    p.add_argument("gcode", metavar="FILE.gcode")
    add_profile_argument(p)
    add_device_arguments(p)
    p.add_argument(
        "--speedup",
        type=bounded_float(0.0, MAX_SPEEDUP),
        default=None,
        help="embedded device: run at most X times real time (default: as fast as the host can)",
    )
    p.add_argument("--json", metavar="R", help="write the job summary as JSON to R")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue exactly where this file's last print stopped (its saved resume point)",
    )
    p.add_argument(
        "--resume-from-layer",
        type=bounded_int(1, 1_000_000),
        metavar="N",
        help="restart the print at layer N (1-based, as shown)",
    )
    p.add_argument("--yes", "-y", action="store_true", help="do not ask for confirmation (resume)")
    p.add_argument(
        "--log",
        metavar="FILE",
        help="job log, JSON lines (default: ~/.local/state/cdprhost/jobs/<name>-<time>.jsonl)",
    )
    p.add_argument(
        "--sim-faults",
        metavar="SPEC",
        help="embedded device: inject faults (same SPEC as sim-device --faults)",
    )
    add_placement_arguments(p, strict=False)
    p.set_defaults(func=run)


def _check_options(args: argparse.Namespace) -> None:
    if args.resume and args.resume_from_layer is not None:
        raise InputError("give --resume or --resume-from-layer, not both", source="--resume")
    if args.sim_faults:
        from firmware_protocol.device.faults import FaultSpec, FaultSpecError

        try:
            FaultSpec.parse(args.sim_faults)
        except FaultSpecError as exc:
            raise InputError(str(exc), source="--sim-faults") from None


def _link_factory(args: argparse.Namespace, profile: Any) -> Any:
    from cdprhost.link import open_link
    from cdprhost.sim.embedded import open_embedded

    baud = args.baud or profile.serial.baud
    if args.port:
        return lambda: open_link(args.port, baud=baud, timeout_s=profile.serial.timeout_s)
    return lambda: open_embedded(speedup=args.speedup, faults=args.sim_faults)


def _confirm(question: str) -> bool:
    if not sys.stdin.isatty():
        return False
    return input(f"{question} [y/N] ").strip().lower() in ("y", "yes")


def run(args: argparse.Namespace) -> int:
    from cdprhost.job.runner import PrintJob, PrintOptions
    from cdprhost.logs import attach_log_file, detach_log_file
    from cdprhost.profile import load_profile, record_device

    _check_options(args)
    gcode = existing_gcode(args.gcode)
    profile = load_profile(args.profile)
    saved = find_resume_point(gcode)
    layer = None
    point = None
    if args.resume:
        if saved is None or not saved.exact:
            raise InputError(
                "no resume point for this file (it completed, it changed since, or it never "
                "stopped part-way); --resume-from-layer N restarts at a layer",
                source=str(gcode),
            )
        point = saved
        setup = resume_setup(saved, setup_from_args(args))  # refuses conflicting options
        placed = "" if setup.default else setup.options()
        question = resume_question(gcode.name, point=saved, placement=placed)
    elif args.resume_from_layer is not None:
        layer = args.resume_from_layer - 1
        question = resume_question(gcode.name, layer=args.resume_from_layer)
    if (args.resume or layer is not None) and not args.yes and not _confirm(question):
        print("not confirmed; nothing moved (use --yes to skip the question)", file=sys.stderr)
        return 1
    if saved is not None and not args.resume and layer is None:
        print(
            f"note: {gcode.name} has a resume point (line {saved.last_line}, layer "
            f"{saved.last_layer}, {saved.reason}); --resume continues there. "
            "This print starts from the beginning.",
            file=sys.stderr,
        )
    log_path = Path(args.log) if args.log else log_path_for(gcode)
    if args.sim_faults is not None and args.port:
        raise InputError("--sim-faults: only for the embedded device (without --port)")
    options = PrintOptions(
        setup=setup_from_args(args), resume_from_layer=layer, resume=point, log_path=log_path
    )
    if args.port:  # a real board: what it announces is kept beside the profile for estimates
        options.record_device = functools.partial(record_device, args.profile)
    if not args.log:
        with contextlib.suppress(OSError):  # a new state folder: the .log goes there too
            log_path.parent.mkdir(parents=True, exist_ok=True)
    handler = attach_log_file(log_path.with_suffix(".log"), quiet=True) if not args.log else None
    events: queue.Queue[Any] = queue.Queue()
    job = PrintJob(gcode, profile, _link_factory(args, profile), options, on_event=events.put)
    outcome: dict[str, Any] = {}

    def work() -> None:
        try:
            outcome["result"] = job.run()
        except BaseException as exc:  # noqa: BLE001 - re-raised in the main thread
            outcome["error"] = exc
        finally:
            events.put(None)

    worker = threading.Thread(target=work, name="print-job", daemon=True)
    try:
        with ProgressView() as view, stop_signals(_on_signal(job, view, outcome)):
            worker.start()
            while True:
                try:
                    event = events.get(timeout=0.5)
                except queue.Empty:
                    continue
                if event is None:
                    break
                if isinstance(event, StateChanged) and event.state is JobState.REFUSED:
                    event = dataclasses.replace(event, reason="")  # the report says why
                view.update(event)
                if (
                    isinstance(event, StateChanged)
                    and event.state is JobState.PAUSED
                    and "asked" not in outcome
                ):
                    outcome["asked"] = True
                    _ask_after_pause(job, event.reason)
                    outcome.pop("asked")
        worker.join()
    finally:
        detach_log_file(handler)
    if "error" in outcome:
        raise outcome["error"]
    result = outcome["result"]
    _report(result, args, log_path)
    if result.status == "refused" and any(v.get("rule") == "syntax" for v in result.violations):
        return 2
    return int(result.exit_code)


def _on_signal(job: Any, view: ProgressView, outcome: dict[str, Any]) -> Callable[[str], None]:
    """The first signal cancels (stop, park, heaters off); the next one e-stops."""
    seen: list[str] = []

    def on_signal(name: str) -> None:
        seen.append(name)
        outcome["interrupted"] = name
        if len(seen) == 1:
            view.say(f"{name}: cancelling (stop, park, heaters off); again to stop at once")
            job.request_cancel(name)
        else:
            view.say(f"{name}: emergency stop")
            threading.Thread(target=job.emergency_stop, name="estop", daemon=True).start()
        if "asked" in outcome:  # leave the question: the answer is given
            raise KeyboardInterrupt

    return on_signal


def _ask_after_pause(job: Any, reason: str) -> None:
    if not sys.stdin.isatty():
        print(f"paused ({reason}) without a terminal to ask: cancelling", file=sys.stderr)
        job.request_cancel()
        return
    while True:
        try:
            answer = input(f"Paused ({reason}; heaters kept). [r]esume or [c]ancel? ")
            answer = answer.strip().lower()
        except (EOFError, KeyboardInterrupt):
            answer = "c"
        if answer in ("r", "resume"):
            job.request_resume()
            return
        if answer in ("c", "cancel"):
            job.request_cancel()
            return


def _report(result: Any, args: argparse.Namespace, log_path: Path) -> None:
    print(f"status: {result.status}")
    reason = result.reason
    if result.status == "refused":
        for v in result.violations[:10]:
            print(f"  line {v['line']}: {v['rule']}: {v['detail']}")
        if len(result.violations) > 10:
            print(f"  ... {len(result.violations) - 10} more (see --json)")
        if result.violations and reason:  # its first line repeats the first violation
            lines = reason.splitlines()
            count = f"{lines[0].split(';')[0]}, the first listed above; nothing moved"
            reason = "\n".join([count, *lines[1:]])
    elif result.segments or result.status != "failed":
        print(
            f"segments: {result.segments}  retransmits: {result.retransmits}  print time: {result.print_time_s:.1f} s "
            f"(estimated {result.estimated_time_s:.1f} s)"
        )
        if result.board:
            print(f"  ({result.board})")
        print(
            f"last line: {result.last_line}  last layer: {result.last_layer}  final steps: {result.final_steps}"
        )
        print(
            "  (final steps: the device's absolute step counters of modules 1, 2, 3 and the "
            "extruder when the job ended)"
        )
    if reason and result.status != "completed":
        print(f"reason: {reason}")
    if result.status != "refused":
        where = (
            f"the device at {args.port}"
            if args.port
            else "the embedded simulated device (no --port: nothing physical moved)"
        )
        print(f"ran on {where}")
        print(f"job log: {log_path} (JSON lines)")
    if result.resume_file:
        print(
            f"resume point saved: {result.resume_file} (continue with --resume, or restart with "
            f"--resume-from-layer {max(result.last_layer or 1, args.resume_from_layer or 1)})"
        )
    if args.json:
        try:
            write_text_atomic(args.json, json.dumps(result.to_json(), indent=1) + "\n")
        except OSError as exc:
            raise InputError(f"cannot write: {exc.strerror or exc}", source=args.json) from None
