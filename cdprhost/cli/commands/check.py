"""`cdprhost check FILE.gcode --profile P [--json R] [--center] [--offset X,Y] [--retarget]
[--strict]`: preflight, exit 1 on any violation."""

from __future__ import annotations

import argparse
import json

from cdprhost.cli.options import (
    add_placement_arguments,
    existing_gcode,
    non_negative_int,
    output_file,
    setup_from_args,
)
from cdprhost.cli.profile_arg import add_profile_argument, load_model
from cdprhost.fileio.atomic import write_text_atomic


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "check", help="preflight a G-code file: workspace along every move, extrusion, commands"
    )
    p.add_argument("gcode", metavar="FILE.gcode", help="sliced G-code file")
    add_profile_argument(p)
    p.add_argument("--json", type=output_file, metavar="R", help="write the report as JSON to R")
    p.add_argument(
        "--max-rows",
        type=non_negative_int,
        default=20,
        help="violations printed (default 20; all are in the JSON)",
    )
    add_placement_arguments(p, strict=True)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cdprhost.preflight import preflight
    from cdprhost.preflight.render import render_text

    gcode = existing_gcode(args.gcode)
    profile, model = load_model(args.profile)
    report = preflight(gcode, profile, model, setup=setup_from_args(args), strict=bool(args.strict))
    print(render_text(report, max_rows=args.max_rows))
    if args.json:
        write_text_atomic(args.json, json.dumps(report.model_dump(mode="json"), indent=1) + "\n")
    return 0 if report.ok else 1
