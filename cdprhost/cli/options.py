"""Option types and the shared placement options of ``check`` and ``print``.

Every option is validated at parse time: a bad value is a usage error (exit 2)
naming the option, never a traceback. Only the standard library is imported here
(fast start); the placement is built lazily.
"""

from __future__ import annotations

import argparse
import math
from typing import Any


def finite_positive(text: str) -> float:
    """A finite number above 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number above 0")
    return v


def _whole(text: str, minimum: int) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if v < minimum:
        raise argparse.ArgumentTypeError(f"{text!r} must be {minimum} or more")
    return v


def positive_int(text: str) -> int:
    return _whole(text, 1)


def non_negative_int(text: str) -> int:
    return _whole(text, 0)


def non_empty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


BAUD_RANGE = (50, 10_000_000)


def add_device_arguments(parser: argparse.ArgumentParser) -> None:
    """``--port DEV`` (a serial device or pyserial URL; without it the embedded simulated
    device) and ``--baud N`` (default: the profile's ``serial.baud``)."""
    from cdprhost.cli.numbers import bounded_int

    parser.add_argument(
        "--port",
        type=non_empty,
        metavar="DEV",
        default=None,
        help="serial device path or pyserial URL (default: the embedded simulated device)",
    )
    parser.add_argument(
        "--baud",
        type=bounded_int(*BAUD_RANGE),
        default=None,
        metavar="N",
        help="baud rate (default: the profile's)",
    )


def offset_xy(text: str) -> tuple[float, float]:
    """``X,Y`` in mm."""
    from cdprhost.errors import InputError
    from cdprhost.gcode.placement import parse_offset

    try:
        return parse_offset(text, "")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[-1]) from None


def add_placement_arguments(p: argparse.ArgumentParser, *, strict: bool) -> None:
    """``--center``, ``--offset X,Y``, ``--retarget``, ``--cancel-object NAME`` (and ``--strict``)."""
    p.add_argument(
        "--center",
        action="store_true",
        help="shift X/Y so the part (from the first layer on) sits at the build volume's centre",
    )
    p.add_argument(
        "--offset",
        type=offset_xy,
        default=(0.0, 0.0),
        metavar="X,Y",
        help="shift the whole program by X,Y mm (after --center / --retarget, if given)",
    )
    p.add_argument(
        "--retarget",
        action="store_true",
        help="for files sliced for another printer: replace their start and end blocks by "
        "the profile's start/end G-code and centre the part",
    )
    p.add_argument(
        "--cancel-object",
        action="append",
        default=[],
        type=non_empty,
        metavar="NAME",
        help="skip the moves of an object (M486 id or label, EXCLUDE_OBJECT name); repeatable",
    )
    if strict:
        p.add_argument(
            "--strict",
            action="store_true",
            help="unknown commands and ignored parameters are errors, not warnings",
        )


def setup_from_args(args: argparse.Namespace) -> Any:
    """The `cdprhost.motion.prepared.Setup` the placement options ask for."""
    from cdprhost.motion.prepared import Setup

    return Setup(
        center=bool(args.center),
        offset=tuple(args.offset),
        retarget=bool(args.retarget),
        cancel_objects=tuple(args.cancel_object),
    )


def existing_gcode(text: str) -> Any:
    """The G-code file ``text`` as a Path; the one wording of ``check`` and ``print`` when
    it is missing (exit 2)."""
    from pathlib import Path

    from cdprhost.errors import InputError

    path = Path(text)
    if not path.is_file():
        reason = "is a folder, not a G-code file" if path.is_dir() else "G-code file not found"
        raise InputError(reason, source=str(path))
    return path


class OutputPath(str):
    """A path a command writes to (an argparse ``type``: :func:`output_file`,
    :func:`output_folder`). Still a ``str``; ``cdprhost.cli.main`` checks every one before
    the command runs, so a folder or an unwritable place is one line and exit 2 before
    any work is done or reported. ``-`` is standard output (files only)."""

    folder = False


class OutputFolder(OutputPath):
    folder = True


def output_file(text: str) -> OutputPath:
    return OutputPath(text)


def output_folder(text: str) -> OutputPath:
    return OutputFolder(text)


def check_outputs(args: argparse.Namespace) -> None:
    """InputError (one line) naming the first output option that cannot be written."""
    from cdprhost.errors import InputError
    from cdprhost.fileio.atomic import output_problem

    for dest, value in vars(args).items():
        if isinstance(value, OutputPath):
            problem = output_problem(value, folder=value.folder)
            if problem:
                flag = "--" + dest.replace("_", "-")
                raise InputError(f"{flag} {value}: {problem}")


def output_paths(args: argparse.Namespace) -> list[str]:
    """Every output path of ``args`` (to recognise an OSError writing one)."""
    return [str(v) for v in vars(args).values() if isinstance(v, OutputPath)]
