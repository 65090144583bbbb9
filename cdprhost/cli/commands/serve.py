"""`cdprhost serve --profile P [--port DEV] [--listen [HOST:]PORT]`: the headless print server.

Answers the slicer upload API (the OctoPrint REST subset) and the web page until SIGTERM or
SIGINT. Every print runs in the printer service (:mod:`cdprhost.service`), found or started
for the device: a server that crashes or is killed leaves the print running, and a server
started again shows it. SIGTERM or SIGINT cancel a running print safely first (the job's
safe-stop path), a second one e-stops it. Without ``--port`` the prints run on the embedded
simulated device (one service per state folder).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
from typing import Any

from cdprhost.cli.numbers import bounded_float
from cdprhost.cli.options import (
    add_device_arguments,
    add_placement_arguments,
    setup_from_args,
)
from cdprhost.cli.profile_arg import add_profile_argument
from cdprhost.cli.signals import stop_signals
from cdprhost.errors import InputError

DEFAULT_MAX_UPLOAD_MB = 256.0


def listen_arg(text: str) -> tuple[str, int]:
    from cdprhost.server.listen import parse_listen

    try:
        return parse_listen(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_server_arguments(p: argparse.ArgumentParser, *, default_listen: bool) -> None:
    """``--listen``, ``--uploads``, ``--max-upload-mb`` (shared with ``tui --listen``)."""
    p.add_argument(
        "--listen",
        type=listen_arg,
        default=("127.0.0.1", 5000) if default_listen else None,
        metavar="[HOST:]PORT",
        help="answer the slicer upload API here"
        + (" (default 127.0.0.1:5000)" if default_listen else "")
        + "; a HOST other than this machine's loopback is warned about",
    )
    p.add_argument(
        "--uploads",
        metavar="DIR",
        help="upload folder (default: ~/.local/state/cdprhost/uploads)",
    )
    p.add_argument(
        "--max-upload-mb",
        type=bounded_float(0.001, 1e6),
        default=DEFAULT_MAX_UPLOAD_MB,
        metavar="MB",
        help=f"largest upload accepted, MB (default {DEFAULT_MAX_UPLOAD_MB:g}; larger: 413)",
    )
    p.add_argument(
        "--camera",
        metavar="0|FILE|URL",
        help="a camera for the web page's snapshot (a device index, a file or a URL)",
    )
    p.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="answer requests whose Host is NAME too (repeatable); by default only the listen "
        "address, and this machine's names when it listens on every address (DNS rebinding)",
    )


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "serve",
        help="headless print server: the slicer upload API (OctoPrint subset) on 127.0.0.1:5000",
    )
    add_profile_argument(p)
    add_device_arguments(p)
    p.add_argument(
        "--speedup",
        type=bounded_float(0.0, 100_000.0),
        default=10.0,
        metavar="X",
        help="embedded device: clock speed-up (default 10)",
    )
    p.add_argument(
        "--clear-fault",
        action="store_true",
        help="a start clears a device fault (watchdog, e-stop) once the machine was checked; "
        "default: a faulted device refuses remote starts (409, the fault explained)",
    )
    add_server_arguments(p, default_listen=True)
    add_placement_arguments(p, strict=False)
    p.set_defaults(func=run)


def start_api(args: argparse.Namespace, printer: Any) -> Any:
    """Key, upload folder, app and server thread (started); says where, once."""
    from cdprhost.server.apikey import KeyFile
    from cdprhost.server.app import create_app
    from cdprhost.server.hosts import HostNames
    from cdprhost.server.listen import ServerThread, exposure_warning, is_loopback
    from cdprhost.server.uploads import UploadFolder

    keys = KeyFile()
    if keys.created:  # the key itself is never printed here: logs are read by others
        print(
            f"API key made now and stored in {keys.path} (mode 600); `cdprhost api-key` prints it",
            file=sys.stderr,
        )
    uploads = UploadFolder(args.uploads)
    try:
        uploads.ensure()
    except OSError as exc:
        raise InputError(
            f"cannot use the upload folder: {exc.strerror or exc}", source=str(uploads.root)
        ) from None
    camera = None
    if getattr(args, "camera", None):
        from cdprhost.server.web_camera import CameraSnapshot

        camera = CameraSnapshot(args.camera)
    host, port = args.listen
    app = create_app(
        printer,
        uploads,
        keys.current,
        max_upload_bytes=int(args.max_upload_mb * 1e6),
        hosts=HostNames.for_listen(host, args.allow_host),
        camera=camera,
    )
    server = ServerThread(app, host, port)
    if not is_loopback(host):
        print(exposure_warning(host, server.port), file=sys.stderr)
    server.start()
    print(
        f"upload API on {server.url} (OctoPrint subset; key in X-Api-Key, see `cdprhost api-key`); "
        f"uploads in {uploads.root}",
        file=sys.stderr,
    )
    return server


def _profile_ref(profile: str) -> str:
    """The profile as the service (another working folder) can find it again."""
    from pathlib import Path

    path = Path(profile)
    return str(path.resolve()) if path.is_file() else profile


def _say_event(event: Any) -> None:
    from cdprhost.job.state import Failure, Notice, StateChanged

    if isinstance(event, StateChanged):
        print(
            f"job {event.state.value}{': ' + event.reason if event.reason else ''}", file=sys.stderr
        )
    elif isinstance(event, Notice):
        print(f"job: {event.text}", file=sys.stderr)
    elif isinstance(event, Failure):
        print(f"job stopped: {event.reason}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from cdprhost.errors import CdprError
    from cdprhost.profile import load_profile
    from cdprhost.server.service_printer import ServicePrinter

    profile = load_profile(args.profile)
    if args.port and not os.path.exists(args.port):  # said before a service is started for it
        raise InputError(
            "no such port (is the device plugged in? try `ls /dev/tty*`)", source=args.port
        )
    printer = ServicePrinter(
        profile,
        port=args.port,
        baud=args.baud,
        speedup=None if args.port else (args.speedup or None),
        setup=setup_from_args(args),
        clear_fault=args.clear_fault,
        # a real board: what it announces is kept beside the profile for the next estimates
        profile_ref=_profile_ref(args.profile) if args.port else None,
        on_event=_say_event,
    )
    try:
        printer.connect()  # finds or starts the printer service; asks the device once
    except CdprError as exc:
        printer.detach()
        raise InputError(str(exc), source=args.port) from None
    status = printer.status()
    if status.busy and status.file is not None:
        who = f", started by {status.started_by}" if status.started_by else ""
        print(
            f"the printer service is printing {status.file.name}{who}: shown here",
            file=sys.stderr,
        )
    stop = threading.Event()
    caught: list[str] = []

    def on_signal(name: str) -> None:
        """First signal: stop (a running print safely, then the server); a second one while
        stopping: emergency stop of the print."""
        caught.append(name)
        if len(caught) > 1:
            print(f"{name} again: emergency stop", file=sys.stderr)
            printer.emergency_stop()
        stop.set()

    server = None
    ended = False
    with stop_signals(on_signal):
        try:
            server = start_api(args, printer)
            while not stop.wait(1.0):  # until a signal: this is the server's life
                pass
            reason = caught[0]
            print(f"{reason}: stopping (a running print is stopped safely first)", file=sys.stderr)
            ended = printer.shutdown(reason)
        finally:
            if server is not None:
                server.stop()
            if not ended:
                printer.shutdown("serve stopped")
    return 0 if ended else 1
