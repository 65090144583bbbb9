"""`cdprhost tui [FILE.gcode] [--profile P] [--port DEV] [--center ...]`: the terminal UI, a
client of the device's printer service (started when none runs): the print lives on when
the UI stops, hangs or is killed, and a UI started later shows it."""

from __future__ import annotations

import argparse
import os
from typing import Any

from cdprhost.cli.commands.serve import add_server_arguments
from cdprhost.cli.options import add_device_arguments, add_placement_arguments, setup_from_args
from cdprhost.cli.profile_arg import add_profile_argument
from cdprhost.errors import InputError


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser("tui", help="terminal UI: connect, print, jog, calibrate, diagnose")
    parser.add_argument(
        "gcode", metavar="FILE.gcode", nargs="?", help="open this file on the print screen"
    )
    add_profile_argument(parser, default="paper-prototype")
    add_device_arguments(parser)
    parser.add_argument(
        "--speedup",
        type=float,
        default=10.0,
        metavar="X",
        help="clock speed-up of the embedded simulated device (default 10)",
    )
    parser.add_argument(
        "--sim-truth",
        metavar="PROFILE",
        help="embedded device only: the hidden true machine seen by the virtual motion capture",
    )
    parser.add_argument(
        "--sim-mocap-dir",
        metavar="DIR",
        help="embedded device only: folder where the virtual motion capture writes its takes",
    )
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="drive the device from this process instead of its printer service (a print "
        "then ends with the UI)",
    )
    add_server_arguments(parser, default_listen=False)
    add_placement_arguments(parser, strict=False)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cdprhost.sim.virtual_mocap import make_observer
    from cdprhost.tui.app import CdprApp
    from cdprhost.tui.control.backend import EMBEDDED
    from cdprhost.tui.control.live import LiveBackend

    if (args.sim_truth is None) != (args.sim_mocap_dir is None):
        raise InputError(
            "--sim-truth and --sim-mocap-dir go together (virtual motion capture needs both)"
        )
    if args.port and args.sim_truth:
        raise InputError(
            "--sim-truth/--sim-mocap-dir apply to the embedded simulated device, not to --port"
        )
    status_interval_s = 1.0
    backend: Any
    # the printer service runs the prints and the device (the virtual motion capture then
    # watches the service's embedded device), unless asked to drive it from here
    in_process = args.in_process
    if in_process:
        observer = make_observer(args.sim_truth, args.sim_mocap_dir)
        backend = LiveBackend(
            args.profile,
            speedup=args.speedup,
            sim_options={"observer": observer} if observer else None,
            idle_pump_s=0.8 * status_interval_s,
            setup=setup_from_args(args),
        )
    else:
        from cdprhost.tui.control.service_backend import ServiceBackend

        sim_mocap = None
        if args.sim_truth is not None:
            from cdprhost.profile import load_profile

            load_profile(args.sim_truth)  # a truth that does not load is said now, not later
            sim_mocap = (args.sim_truth, args.sim_mocap_dir)
        backend = ServiceBackend(
            args.profile, speedup=args.speedup, setup=setup_from_args(args), sim_mocap=sim_mocap
        )
    if args.gcode is not None and not os.path.isfile(args.gcode):
        raise InputError("G-code file not found", source=args.gcode)
    app = CdprApp(
        backend,
        port=args.port or EMBEDDED,
        baud=args.baud,
        status_interval_s=status_interval_s,
        open_file=args.gcode,
    )
    if args.listen is None:
        return int(app.run() or 0)
    from cdprhost.cli.commands.serve import start_api

    if in_process:  # the page reads the UI's own link
        from cdprhost.tui.control.upload_bridge import TuiPrinter

        bridge = TuiPrinter(app)
        server = start_api(args, bridge)  # the TUI's own quit stops a running print safely
        bridge.announce(f"listening on {server.url} (slicer uploads; key: `cdprhost api-key`)")
        try:
            return int(app.run() or 0)
        finally:
            server.stop()
    return _run_with_page(args, app)


def _run_with_page(args: argparse.Namespace, app: Any) -> int:
    """The UI and the web page as two clients of the device's printer service: the page
    has the layer view and every control it has under ``serve``, and a print started from
    either goes on when the UI quits."""
    from cdprhost.cli.commands.serve import start_api
    from cdprhost.errors import CdprError
    from cdprhost.profile import load_profile
    from cdprhost.server.service_printer import ServicePrinter

    printer = ServicePrinter(
        load_profile(args.profile),
        port=args.port,
        baud=args.baud,
        speedup=None if args.port else (args.speedup or None),
        setup=setup_from_args(args),
        clear_fault=False,  # a faulted device is cleared at the machine (the UI), not by a page
    )
    try:
        printer.connect()  # finds or starts the service the UI attaches to
    except CdprError as exc:
        printer.detach()
        raise InputError(str(exc), source=args.port) from None
    server = start_api(args, printer)
    try:
        return int(app.run() or 0)
    finally:
        server.stop()
        printer.detach()  # a print goes on in the service
