"""Entry point of the ``cdprhost`` console script.

Start-up imports only what the command asked for: the table below names each command's
module and one-line help, so ``--version``, ``--help`` and the parser of one command never
import the others (``check`` and ``print`` never load calibration, diagnosis, plotting or
the TUI). ``tests/cli/test_startup.py`` keeps the table and the modules in step.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
from types import ModuleType

from cdprhost import __version__

# command -> (module in cdprhost.cli.commands, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "api-key": ("api_key", "print (or replace) the API key the print server requires"),
    "autotune": ("autotune", "PID autotune of a heater on the device (M303); gains to the profile"),
    "calibrate": (
        "calibrate",
        "kinematic calibration: plan poses, identify parameters, guided wizard",
    ),
    "check": ("check", "preflight a G-code file: workspace along every move, extrusion, commands"),
    "diagnose": (
        "diagnose",
        "find, name and add the physics the calibrated model lacks (model discrepancy workflow)",
    ),
    "ik": ("kinematics", "points (x,y,z) -> slider displacements and steps, effects compensated"),
    "fk": ("kinematics", "slider displacements (s1,s2,s3) -> effector points, effects predicted"),
    "print": (
        "print_cmd",
        "print a G-code file (embedded simulated device unless --port is given)",
    ),
    "profile": ("profile", "show, validate or export machine profiles"),
    "serve": (
        "serve",
        "headless print server: the slicer upload API (OctoPrint subset) on 127.0.0.1:5000",
    ),
    "sim-device": ("sim_device", "run the simulated device on a pseudo-terminal (prints its path)"),
    "tui": ("tui", "terminal UI: connect, print, jog, calibrate, diagnose"),
}


def command_word(argv: list[str]) -> str | None:
    """The command in ``argv`` (top-level options are all flags, so it is the first word)."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s module is imported (None: none, all commands listed)."""
    parser = argparse.ArgumentParser(
        prog="cdprhost",
        description="Host software for a cable-driven parallel robot 3D printer.",
    )
    parser.add_argument("--version", action="version", version=f"cdprhost {__version__}")
    parser.add_argument(
        "--verbose", "-v", action="count", default=0, help="log more (-v info, -vv debug) to stderr"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    if command in COMMANDS:
        load_command(COMMANDS[command][0]).register(sub)
    for name, (_, one_line) in COMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=one_line)
    return parser


def load_command(module: str) -> ModuleType:
    """A command module (``register(subparsers)``, and the ``run`` functions it sets)."""
    return importlib.import_module(f"cdprhost.cli.commands.{module}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(command_word(argv))
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    from cdprhost.cli.options import check_outputs, output_paths
    from cdprhost.errors import CdprError
    from cdprhost.fileio.atomic import data_to_stdout, is_stdout
    from cdprhost.logs import configure_logging

    configure_logging(args.verbose)
    try:
        check_outputs(args)  # a folder or an unwritable place: said before any work
        if any(is_stdout(p) for p in output_paths(args)):
            # the data goes to stdout alone (`--json - | jq`); what the command says, to stderr
            with data_to_stdout(sys.stdout), contextlib.redirect_stdout(sys.stderr):
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    except CdprError as exc:
        print(f"cdprhost {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # e.g. `cdprhost profile show P | head`: the reader left, not an error
        sys.stderr.close()
        return 0
    except OSError as exc:
        where = _output_named(exc, output_paths(args))
        if where is None:
            raise
        print(
            f"cdprhost {args.command}: error: {where}: cannot write: {exc.strerror}",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print(f"cdprhost {args.command}: interrupted", file=sys.stderr)
        return 130


def _output_named(exc: OSError, outputs: list[str]) -> str | None:
    """The output path an OSError is about (the file, its folder or its temporary file
    beside it), or None when it is about something else (a device, an input)."""
    import os

    names = [os.fspath(n) for n in (exc.filename, exc.filename2) if n is not None]
    for out in outputs:
        real = os.path.realpath(out)
        folder, base = os.path.split(real)
        for name in names:
            path = os.path.realpath(name)
            if path in (real, folder) or path.startswith(real + os.sep):
                return out
            if os.path.dirname(path) == folder and os.path.basename(path).startswith(f".{base}."):
                return out
    return None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
