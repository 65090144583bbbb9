"""`cdprhost api-key [--rotate]`: print (or replace) the key the print server requires."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "api-key",
        help="print (or replace) the API key the print server requires",
        description="The key slicers send (X-Api-Key) to `cdprhost serve` and `tui --listen`. "
        "Made at first use in $XDG_CONFIG_HOME/cdprhost/api-key (~/.config/...), mode 600.",
    )
    p.add_argument(
        "--rotate",
        action="store_true",
        help="replace the key; a running server refuses the old one from now on",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cdprhost.server.apikey import key_path, load_or_create, rotate

    path = key_path()
    if args.rotate:
        key = rotate(path)
        print(
            f"new API key written to {path} (mode 600); the old one no longer works",
            file=sys.stderr,
        )
    else:
        key, created = load_or_create(path)
        if created:
            print(f"API key made now and stored in {path} (mode 600)", file=sys.stderr)
    print(key)
    return 0
