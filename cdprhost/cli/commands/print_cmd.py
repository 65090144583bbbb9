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
import json
import queue
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cdprhost.cli.numbers import bounded_float, bounded_int
from cdprhost.cli.options import (
    add_device_arguments,
    add_placement_arguments,
    existing_gcode,
    output_file,
    setup_from_args,
)
from cdprhost.cli.profile_arg import add_profile_argument
from cdprhost.cli.progress_view import ProgressView
from cdprhost.cli.signals import stop_signals
from cdprhost.errors import InputError, JobFailed
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.job.resume import find_resume_point, log_path_for, resume_question, resume_setup
from cdprhost.job.state import JobState, StateChanged
from cdprhost.service import wire
from cdprhost.service.client import ServiceClient, attach

MAX_SPEEDUP = 100_000.0
START_ID = 1  # the start is the first command a print sends
HOST_LATE_TOLD_S = 0.1  # the summary names a host that came this late to a refill, or later


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "print", help="print a G-code file (embedded simulated device unless --port is given)"
    )
    p.add_argument("gcode", metavar="FILE.gcode", nargs="?")
    add_profile_argument(p, required=False)  # required to print; --attach needs none
    add_device_arguments(p)
    p.add_argument(
        "--speedup",
        type=bounded_float(0.0, MAX_SPEEDUP),
        default=None,
        help="embedded device: run at most X times real time (default: as fast as the host can)",
    )
    p.add_argument(
        "--json", type=output_file, metavar="R", help="write the job summary as JSON to R"
    )
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
    p.add_argument(
        "--attach",
        action="store_true",
        help="watch the print running on --port (its printer service) instead of starting one; "
        "Ctrl-C stops watching, never the print",
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
    if args.attach:
        if not args.port:
            raise InputError(
                "--attach watches the print on a device: give its --port (a print on the "
                "embedded device belongs to the command that started it)",
                source="--attach",
            )
        return
    if args.gcode is None:
        raise InputError("give the G-code file to print (or --attach to watch a print)")
    if args.profile is None:
        raise InputError("give the machine profile", source="--profile")
    if args.resume and args.resume_from_layer is not None:
        raise InputError("give --resume or --resume-from-layer, not both", source="--resume")
    if args.sim_faults:
        from firmware_protocol.device.faults import FaultSpec, FaultSpecError

        try:
            FaultSpec.parse(args.sim_faults)
        except FaultSpecError as exc:
            raise InputError(str(exc), source="--sim-faults") from None


def _confirm(question: str) -> bool:
    if not sys.stdin.isatty():
        return False
    return input(f"{question} [y/N] ").strip().lower() in ("y", "yes")


def run(args: argparse.Namespace) -> int:
    from cdprhost.profile import load_profile

    _check_options(args)
    if args.attach:
        return _watch(args)
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
    if not args.log:
        with contextlib.suppress(OSError):  # a new state folder: the .log goes there too
            log_path.parent.mkdir(parents=True, exist_ok=True)
    spec = wire.StartJob(
        gcode=str(gcode.resolve()),
        profile=profile.model_dump(mode="json"),
        port=args.port,
        baud=args.baud,
        speedup=args.speedup,
        sim_faults=args.sim_faults,
        setup=setup_from_args(args).to_json(),
        resume=point is not None,
        resume_from_layer=layer,
        log_path=str(log_path if log_path.is_absolute() else log_path.absolute()),
        job_log_file=not args.log,
        # a real board: what it announces is kept beside the profile for later estimates
        profile_ref=_profile_ref(args.profile) if args.port else None,
    )
    client = attach(args.port, "print", replay=False)
    try:
        outcome = _follow(client, starter=True, start=wire.Start(job=spec))
    finally:
        client.close()
    return _finish(outcome, args, log_path)


def _profile_ref(profile: str) -> str:
    """The profile as the service (another working folder) can find it again."""
    path = Path(profile)
    return str(path.resolve()) if path.is_file() else profile


def _watch(args: argparse.Namespace) -> int:
    """``--attach``: the running (or last) print on ``--port``, to its end."""
    client = attach(args.port, "print --attach", replay=True, start=False)
    try:
        if client.welcome is not None and client.welcome.job == "none":
            print(f"no print has run on {args.port} since its service started", file=sys.stderr)
            return 1
        outcome = _follow(client, starter=False)
    finally:
        client.close()
    if "error" in outcome:
        print(outcome["error"], file=sys.stderr)
        return 1
    return _finish(outcome, args, None)


def _finish(outcome: dict[str, Any], args: argparse.Namespace, log_path: Path | None) -> int:
    from cdprhost.job.options import PrintResult

    if "error" in outcome:
        raise JobFailed(outcome["error"])
    result = PrintResult(**outcome["result"])
    _report(result, args, log_path)
    if result.status == "refused" and any(v.get("rule") == "syntax" for v in result.violations):
        return 2
    return int(result.exit_code)


def _follow(
    client: ServiceClient, *, starter: bool, start: wire.Start | None = None
) -> dict[str, Any]:
    """Send ``start`` (once a signal can cancel it), then show the job's events until its
    result; the starter also answers a pause and turns signals into a cancel (then an
    e-stop). A watcher leaves on a signal: the print goes on."""
    outcome: dict[str, Any] = {}
    with ProgressView() as view, stop_signals(_on_signal(client, view, outcome, starter)):
        if start is not None:
            client.send(start)
        while "result" not in outcome and "error" not in outcome:
            if outcome.get("detached"):
                outcome["error"] = "stopped watching; the print goes on in the printer service"
                break
            try:
                message = client.inbox.get(timeout=0.5)
            except queue.Empty:
                continue
            if message is None:
                outcome["error"] = (
                    f"the printer service went away ({client.gone or 'no reason'}); "
                    f"its log: {client.files.log}"
                )
                break
            _take(message, client, view, outcome, starter)
    return outcome


def _take(
    message: Any, client: ServiceClient, view: ProgressView, outcome: dict[str, Any], starter: bool
) -> None:
    if isinstance(message, wire.EventMsg):
        event = wire.event_from_json(message.event)
        if isinstance(event, StateChanged) and event.state is JobState.REFUSED:
            event = dataclasses.replace(event, reason="")  # the report says why
        view.update(event)
        if (
            starter
            and isinstance(event, StateChanged)
            and event.state is JobState.PAUSED
            and "asked" not in outcome
        ):
            outcome["asked"] = True
            _ask_after_pause(client, event.reason)
            outcome.pop("asked")
    elif isinstance(message, wire.ResultMsg):
        if message.result is not None:
            outcome["result"] = message.result
        else:
            outcome["error"] = message.error
    elif isinstance(message, wire.Reply) and not message.ok:
        if message.id == START_ID:  # the start was refused
            outcome["error"] = message.error
        else:
            view.say(message.error)
    elif isinstance(message, wire.LogMsg):
        view.say(f"cdprhost: {message.level} {message.text}")


def _on_signal(
    client: ServiceClient, view: ProgressView, outcome: dict[str, Any], starter: bool
) -> Callable[[str], None]:
    """The starter: the first signal cancels (stop, park, heaters off); the next e-stops.
    A watcher (``--attach``) stops watching."""
    seen: list[str] = []

    def on_signal(name: str) -> None:
        seen.append(name)
        if not starter:
            outcome["detached"] = True
            return
        outcome["interrupted"] = name
        if len(seen) == 1:
            view.say(f"{name}: cancelling (stop, park, heaters off); again to stop at once")
            client.command(wire.Cancel(reason=name))
        else:
            view.say(f"{name}: emergency stop")
            client.command(wire.Estop())
        if "asked" in outcome:  # leave the question: the answer is given
            raise KeyboardInterrupt

    return on_signal


def _ask_after_pause(client: ServiceClient, reason: str) -> None:
    if not sys.stdin.isatty():
        print(f"paused ({reason}) without a terminal to ask: cancelling", file=sys.stderr)
        client.command(wire.Cancel())
        return
    while True:
        try:
            answer = input(f"Paused ({reason}; heaters kept). [r]esume or [c]ancel? ")
            answer = answer.strip().lower()
        except (EOFError, KeyboardInterrupt):
            answer = "c"
        if answer in ("r", "resume"):
            client.command(wire.Resume())
            return
        if answer in ("c", "cancel"):
            client.command(wire.Cancel())
            return


def _report(result: Any, args: argparse.Namespace, log_path: Path | None) -> None:
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
        if result.host_late_s >= HOST_LATE_TOLD_S:
            print(
                f"  (this PC came up to {result.host_late_s:.2f} s late to refill the device, "
                f"so the host kept {result.lead_s:.1f} s of motion ahead or more: a pause or a "
                "speed change took effect that much later; a less busy PC needs less)"
            )
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
        if log_path is not None:
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
