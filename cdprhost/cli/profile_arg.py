"""The shared ``--profile P`` argument and its loading into a machine model."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import MachineProfile


def add_profile_argument(
    parser: argparse.ArgumentParser, *, required: bool = True, default: str | None = None
) -> None:
    parser.add_argument(
        "--profile",
        "-p",
        required=required and default is None,
        default=default,
        metavar="P",
        help="machine profile: a shipped name (paper-simulation, paper-prototype), a name in the user folder, or a TOML path",
    )


def load_model(ref: str) -> tuple[MachineProfile, MachineModel]:
    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import load_profile

    profile = load_profile(ref)
    return profile, MachineModel.from_profile(profile)
