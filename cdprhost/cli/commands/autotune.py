"""`cdprhost autotune "M303 E0 S210 C8" --profile P [--port DEV] [--save FILE]`: the
device's PID autotune of a heater (E0 the hotend, E-1 the bed), the gains printed in
M301 form and, with ``--save``, stored in the machine profile (sent to the device at
every connect from then on)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from cdprhost.cli.options import add_device_arguments, finite_positive
from cdprhost.cli.profile_arg import add_profile_argument
from cdprhost.errors import InputError

if TYPE_CHECKING:
    from cdprhost.gcode import PidAutotune

TUNE_TIMEOUT_S = 30 * 60.0


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "autotune",
        help="PID autotune of a heater on the device (M303), gains stored in the profile",
    )
    p.add_argument("command", metavar='"M303 ..."', help="e.g. 'M303 E0 S210 C8' (bed: E-1)")
    add_profile_argument(p)
    add_device_arguments(p)
    p.add_argument(
        "--speedup", type=finite_positive, help="embedded device: at most X times real time"
    )
    p.add_argument(
        "--save",
        metavar="FILE",
        help="write the profile with the new gains to FILE (the profile's own file: '-')",
    )
    p.set_defaults(func=run)


def parse_m303(text: str) -> PidAutotune:
    from cdprhost.gcode import PidAutotune, read_program

    items = [i for i in read_program([text], name="command") if isinstance(i, PidAutotune)]
    if len(items) != 1:
        raise InputError("expected one M303 line, e.g. 'M303 E0 S210 C8'", source=text)
    return items[0]


def run(args: argparse.Namespace) -> int:
    from cdprhost.link import open_link
    from cdprhost.machine.commands import HEATER_IDS, device_messages
    from cdprhost.machine.operations import Machine
    from cdprhost.profile import load_profile, save_profile
    from cdprhost.profile.loader import resolve_profile_path
    from cdprhost.profile.models import PidGains, with_pid
    from cdprhost.sim.embedded import open_embedded

    tune = parse_m303(args.command)
    profile = load_profile(args.profile)
    limit = profile.heaters.hotend_max_c if tune.heater == "hotend" else profile.heaters.bed_max_c
    if not 0 < tune.target_c <= limit:
        raise InputError(f"S{tune.target_c:g}: {tune.heater} target must be within 0-{limit:g} C")
    if args.port:
        baud = args.baud or profile.serial.baud
        link = open_link(args.port, baud=baud, timeout_s=profile.serial.timeout_s)
    else:
        link = open_embedded(speedup=args.speedup)
    with link:
        machine = Machine(link, profile)
        msgs = device_messages(
            tune, model=machine.model, home_mm=profile.drive.home_mm, clock_hz=machine.clock_hz
        )
        print(f"autotune of the {tune.heater} at {tune.target_c:g} C, {tune.cycles} cycles ...")
        link.send(*msgs)
        link.wait_idle(TUNE_TIMEOUT_S)
        found = link.tuned_gains.get(HEATER_IDS[tune.heater])
    if found is None:
        raise InputError("the device reported no gains (a 2.0 firmware has no autotune)")
    gains = PidGains(kp=found[0] / 1000, ki=found[1] / 1000, kd=found[2] / 1000)
    print(f"M301 P{gains.kp:.2f} I{gains.ki:.2f} D{gains.kd:.2f}  ({tune.heater})")
    if args.save:
        path = resolve_profile_path(args.profile) if args.save == "-" else Path(args.save)
        save_profile(with_pid(profile, tune.heater, gains), path)
        print(f"saved to {path}: sent to the device at every connect")
    return 0
