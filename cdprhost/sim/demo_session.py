"""A demonstration calibration session from the simulated world (``calibrate demo``).

So that the calibration and diagnosis commands can be tried without a machine or a
motion capture: a hidden true machine (the profile's geometry off by up to 2 mm per
parameter, plus one catalogue effect at a realistic magnitude) is measured at planned
poses (D-optimal fit poses plus check poses, as the wizard plans them) by the virtual
motion capture's realistic disturbances, and written as a session folder of Motive CSV
takes: what ``calibrate identify`` and ``diagnose`` read.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from itertools import permutations
from pathlib import Path

import numpy as np

from cdprhost.calibration.planning import plan_poses
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.kinematics.machine import MachineModel
from cdprhost.profile.models import MachineProfile
from cdprhost.sim.scenarios import hidden_truth, session_times
from cdprhost.sim.synthetic_session import write_measured_session
from cdprhost.sim.virtual_mocap import REALISTIC

#: fit poses of the demo: enough for a diagnosis (which needs 8 poses) and its held-out test
DEMO_FIT_POSES = 12
DEMO_CHECK_POSES = 3
DEMO_EFFECT = "cable_elasticity"


@dataclass(frozen=True)
class DemoSession:
    directory: Path
    truth: MachineModel
    effect: str | None
    roles: tuple[str, ...]


def write_demo_session(
    directory: str | os.PathLike[str],
    profile: MachineProfile,
    *,
    effect: str | None = DEMO_EFFECT,
    n_fit: int = DEMO_FIT_POSES,
    n_check: int = DEMO_CHECK_POSES,
    seed: int = 1,
) -> DemoSession:
    """Write the session folder (refuses to write into a non-empty folder)."""
    out = Path(directory)
    if out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out}: not empty; give a new folder for the demo session")
    nominal = MachineModel.from_profile(profile)
    rng = np.random.default_rng(seed)
    truth = hidden_truth(nominal, rng, effect)
    plan = plan_poses(nominal, n_fit, n_check=n_check, seed=seed)
    write_measured_session(
        out,
        truth,
        nominal,
        plan.poses,
        session_times(len(plan.poses), rng),
        realism=REALISTIC,
        rate_hz=120.0,
        duration_s=2.0,
        profile_name=profile.name,
        roles=plan.roles,
        seed=seed,
    )
    return DemoSession(out, truth, effect, plan.roles)


def truth_profile(profile: MachineProfile, truth: MachineModel) -> MachineProfile:
    """The hidden true machine as a profile (``--sim-truth`` of the wizard)."""
    return profile.with_geometry(
        truth.geometry.outlets,
        truth.geometry.initial_lengths,
        name=f"{profile.name}-hidden-truth",
        description="the hidden true machine of `cdprhost calibrate demo` (do not peek)",
        effects=truth.effects.to_tables(),
    )


def sim_truth_problem(
    nominal: MachineModel, truth: MachineModel, limit_mm: float, truth_name: str, profile_name: str
) -> str | None:
    """Why a simulated truth cannot be calibrated from ``nominal`` by the wizard, or None.

    The wizard refuses a take that lands more than ``limit_mm`` from its commanded pose;
    a truth that far from the nominal model (over a coarse workspace grid) would have
    every take refused. A different numbering of the modules is the usual cause."""
    points = workspace_grid(nominal, heights=(150.0, 250.0), spacing_mm=40.0)
    gap = _gap(nominal, truth, points)
    if gap <= limit_mm:
        return None
    text = (
        f"--sim-truth {truth_name}: the simulated machine puts the effector up to "
        f"{gap:.0f} mm from where profile {profile_name} commands it, and the wizard refuses "
        f"a take more than {limit_mm:g} mm from its pose, so every take would be refused"
    )
    for perm in permutations(range(3)):
        if perm == (0, 1, 2):
            continue
        swapped = truth.with_geometry(
            CableGeometry(
                truth.geometry.outlets[list(perm)], truth.geometry.initial_lengths[list(perm)]
            )
        )
        if _gap(nominal, swapped, points) <= limit_mm:
            names = ", ".join(str(k + 1) for k in perm)
            return (
                f"{text}. Its modules are numbered differently: the profile's modules 1, 2, 3 "
                f"are its modules {names}. Give a truth numbered as the profile (or calibrate "
                f"--profile {truth_name} itself)"
            )
    return f"{text}. Give a truth within a few millimetres of the profile"


def _gap(nominal: MachineModel, truth: MachineModel, points: np.ndarray) -> float:
    reached = truth.fk(nominal.ik(points))
    gap = np.linalg.norm(reached - points, axis=1)
    return float(np.max(np.where(np.isfinite(gap), gap, np.inf)))
