"""`cdprhost profile show P` / `cdprhost profile check PATH` /
`cdprhost profile export-slicer P --to prusaslicer|cura|orca --out FILE` /
`cdprhost profile export-firmware P --to klipper --out FILE`."""

from __future__ import annotations

import argparse

from cdprhost.cli.options import output_file
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
    export = psub.add_parser(
        "export-slicer",
        help="write a slicer printer definition for this machine (bed, height, limits, "
        "start/end G-code)",
    )
    export.add_argument("profile", metavar="P")
    export.add_argument(
        "--to", required=True, choices=("prusaslicer", "cura", "orca"), help="the slicer"
    )
    export.add_argument(
        "--out", type=output_file, required=True, metavar="FILE", help="where to write it"
    )
    export.set_defaults(func=run_export)
    firmware = psub.add_parser(
        "export-firmware",
        help="write a firmware configuration for this machine's kinematics (Klipper winch), "
        "saying what it cannot express",
    )
    firmware.add_argument("profile", metavar="P")
    firmware.add_argument("--to", required=True, choices=("klipper",), help="the firmware")
    firmware.add_argument(
        "--out", type=output_file, required=True, metavar="FILE", help="where to write it"
    )
    firmware.set_defaults(func=run_export_firmware)


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


def run_export(args: argparse.Namespace) -> int:
    import numpy as np

    from cdprhost.fileio.atomic import write_text_atomic
    from cdprhost.kinematics import MachineModel
    from cdprhost.preflight.placement import printable_bed
    from cdprhost.profile.slicer_export import export

    profile = load_profile(args.profile)
    model = MachineModel.from_profile(profile)
    bed = printable_bed(model, np.asarray(profile.build_volume.bed_origin, dtype=float))
    write_text_atomic(args.out, export(profile, args.to, bed.polygon, bed.height_mm))
    corners = ", ".join(f"({x:g}, {y:g})" for x, y in bed.polygon)
    print(
        f"{args.out}: {args.to} printer '{profile.name}': bed triangle {corners} mm "
        f"(origin at its centre), height {bed.height_mm:g} mm"
    )
    return 0


def run_export_firmware(args: argparse.Namespace) -> int:
    import numpy as np

    from cdprhost.fileio.atomic import write_text_atomic
    from cdprhost.kinematics import MachineModel
    from cdprhost.kinematics.winch import dropped_effects, winch_equivalent
    from cdprhost.profile.klipper_export import NOT_IN_KLIPPER, dropped_lines, klipper_config

    profile = load_profile(args.profile)
    model = MachineModel.from_profile(profile)
    origin = np.asarray(profile.build_volume.bed_origin, dtype=float)
    winch = winch_equivalent(model, origin, np.asarray(profile.drive.home_mm, dtype=float))
    dropped = dropped_effects(model, origin, np.asarray(profile.drive.home_mm, dtype=float))
    write_text_atomic(args.out, klipper_config(profile, winch, dropped))
    folded = (
        " (drive_scale folded into rotation_distance)" if "drive_scale" in profile.effects else ""
    )
    print(f"{args.out}: Klipper winch kinematics for '{profile.name}'{folded}")
    if dropped:
        print("calibrated effects Klipper cannot express:")
    else:
        print("calibrated effects: every one expressed (the config reproduces the model exactly)")
    for line in dropped_lines(dropped):
        print(f"  {line}")
    print("not done by Klipper's winch kinematics (cdprhost does them):")
    for line in NOT_IN_KLIPPER:
        print(f"  {line.split(':')[0]}")
    return 0
