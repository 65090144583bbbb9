"""Entry point of the ``cdprhost`` console script."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from cdprhost import __version__
from cdprhost.cli import commands as commands_pkg
from cdprhost.errors import CdprError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cdprhost",
        description="Host software for a cable-driven parallel robot 3D printer.",
    )
    parser.add_argument("--version", action="version", version=f"cdprhost {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands_pkg.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands_pkg.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except CdprError as exc:
        print(f"cdprhost {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"cdprhost {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `cdprhost profile show P | head`: the reader left, not an error
        sys.stderr.close()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
