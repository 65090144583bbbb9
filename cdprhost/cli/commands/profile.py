"""`cdprhost profile show P` / `cdprhost profile check PATH`."""

from __future__ import annotations

import argparse

from cdprhost.profile import load_profile, profile_to_toml
from cdprhost.profile.loader import resolve_profile_path


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser("profile", help="show or validate machine profiles")
    psub = parser.add_subparsers(dest="profile_command", metavar="ACTION", required=True)
    show = psub.add_parser("show", help="print a profile (validated) as TOML")
    show.add_argument("profile", metavar="P")
    show.set_defaults(func=run_show)
    check = psub.add_parser(
        "check", help="validate a profile file; exit 2 with one line per problem"
    )
    check.add_argument("path", metavar="PATH")
    check.set_defaults(func=run_check)


def run_show(args: argparse.Namespace) -> int:
    profile = load_profile(args.profile)
    print(f"# {resolve_profile_path(args.profile)}")
    print(profile_to_toml(profile), end="")
    return 0


def run_check(args: argparse.Namespace) -> int:
    profile = load_profile(args.path)
    effects = ", ".join(profile.effects) or "none (ideal model)"
    print(f"{args.path}: ok (profile '{profile.name}', effects: {effects})")
    return 0
