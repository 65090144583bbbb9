"""`cdprhost diagnose SESSION --profile P [--json R] [--out augmented.toml] [--plot gap.png]
[--write [PROFILE]]`."""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from cdprhost.cli.numbers import bounded_int
from cdprhost.cli.options import output_file
from cdprhost.cli.profile_arg import add_profile_argument, load_model
from cdprhost.diagnosis.augment import augmented_profile
from cdprhost.diagnosis.report import to_json, to_text
from cdprhost.diagnosis.session_input import diagnose_session
from cdprhost.diagnosis.workflow import DiagnosisSettings
from cdprhost.effects.registry import CATALOGUE
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.profile import save_profile


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "diagnose",
        help="find, name and add the physics the calibrated model lacks (model discrepancy workflow)",
        description="Fit the base model to a calibration session, test the misfit against the noise floor, "
        "name the catalogue effect that explains it (or say none / ambiguous / unexplained), and "
        "write the augmented profile. Exit 0 whatever the verdict; 2 on bad input.",
    )
    p.add_argument(
        "session",
        metavar="SESSION",
        help="calibration session folder (session.toml, poses.csv, takes/)",
    )
    add_profile_argument(p)
    p.add_argument(
        "--json", type=output_file, metavar="R", help="write the machine-readable report here"
    )
    p.add_argument(
        "--out",
        type=output_file,
        metavar="augmented.toml",
        help="write the profile with the final model (geometry + effects)",
    )
    p.add_argument(
        "--write",
        nargs="?",
        const="",
        metavar="PROFILE",
        help="write the improved profile over PROFILE (default: the --profile file; a shipped "
        "profile goes to your profiles folder instead, said first), only when the diagnosis "
        "names an effect that shrinks the held-out error; without it a terminal asks",
    )
    p.add_argument(
        "--plot",
        type=output_file,
        metavar="gap.png",
        help="write the per-pose held-out error figure (PNG)",
    )
    p.add_argument(
        "--folds",
        type=bounded_int(2, 100),
        default=DiagnosisSettings.folds,
        metavar="K",
        help="grouped K-fold by pose for held-out errors (default %(default)s)",
    )
    p.add_argument(
        "--alpha",
        type=float,
        default=DiagnosisSettings.alpha,
        help="family-wise level of the nested tests (Holm; default %(default)s)",
    )
    p.add_argument(
        "--effects",
        metavar="NAMES",
        help=f"comma-separated candidates (default: all of {', '.join(CATALOGUE)})",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no terminal report")
    p.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> DiagnosisSettings:
    settings = DiagnosisSettings()
    if args.folds < 2:
        raise InputError(f"--folds must be at least 2, got {args.folds}")
    if not 0 < args.alpha < 1:
        raise InputError(f"--alpha must lie in (0, 1), got {args.alpha}")
    candidates = None
    if args.effects:
        candidates = tuple(n.strip() for n in args.effects.split(",") if n.strip())
        unknown = [n for n in candidates if n not in CATALOGUE]
        if unknown:
            raise InputError(
                f"--effects: unknown effect(s) {', '.join(unknown)} (known: {', '.join(CATALOGUE)})"
            )
    return replace(settings, folds=args.folds, alpha=args.alpha, candidates=candidates)


def run(args: argparse.Namespace) -> int:
    settings = _settings(args)
    profile, model = load_model(args.profile)
    result, data = diagnose_session(args.session, model, settings)
    rejected = [
        {"pose": r.pose, "take": r.take, "reason": r.reason, "text": str(r)} for r in data.rejected
    ]
    if not args.quiet:
        print(to_text(result, session=str(args.session)), end="")
        for r in data.rejected:
            print(f"refused take: {r}", file=sys.stderr)
        for w in data.warnings:
            print(f"warning: {w}", file=sys.stderr)
    if args.json:
        write_text_atomic(
            args.json,
            json.dumps(to_json(result, session=str(args.session), rejected=rejected), indent=2)
            + "\n",
        )
    if args.out:
        save_profile(augmented_profile(profile, result, session=str(args.session)), args.out)
    if args.plot:
        from cdprhost.diagnosis.plot import save_gap_plot  # matplotlib only when asked

        save_gap_plot(result, args.plot)
    _write_back(args, profile, result)
    return 0


def _target(ref: str) -> Path:
    """``--write``'s PROFILE: a file, or a name in the user's profiles folder."""
    from cdprhost.profile.loader import user_profile_dir

    path = Path(ref).expanduser()
    if path.suffix == ".toml" or os.sep in ref:
        return path
    return user_profile_dir() / f"{ref}.toml"


def _asked() -> bool:
    """Interactive only: a terminal on both ends (scripts and pipes are never asked)."""
    return sys.stdin.isatty() and sys.stdout.isatty()


def _write_back(args: argparse.Namespace, profile: Any, result: Any) -> None:
    """``--write``, or a question on a terminal: the improved profile, written atomically."""
    from cdprhost.diagnosis.write_back import write_improved, write_plan
    from cdprhost.profile.loader import resolve_profile_path

    asked = args.write is None and not args.quiet and _asked()
    if args.write is None and not asked:
        return
    plan = write_plan(
        result, _target(args.write) if args.write else resolve_profile_path(args.profile)
    )
    if plan.refused:
        if args.write is not None:
            print(f"profile not written: {plan.refused}", file=sys.stderr)
        return
    if asked:
        try:
            answer = input(f"{plan.question()} [y/N] ")
        except EOFError:
            answer = ""
        if answer.strip().lower() not in ("y", "yes"):
            print("profile not written")
            return
    elif plan.note:
        print(plan.note, file=sys.stderr)
    try:
        path = write_improved(profile, result, plan, session=str(args.session))
    except OSError as exc:
        raise InputError(f"cannot write {plan.path}: {exc.strerror or exc}") from None
    print(f"wrote the improved profile to {path}")
