"""Simulated measurement sessions at the array level (no files).

A *true* machine (geometry and effects the host does not know) is commanded
through a *nominal* model: the host computes slider targets with the nominal IK,
the true machine goes wherever those targets really put it, and motion capture
measures that point with noise. Used by the calibration benchmark, the diagnosis
tests, and (through the take writers) the virtual motion capture.
"""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.fitting import Observations
from cdprhost.effects.base import MotionContext
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel


def perturbed_geometry(
    nominal: CableGeometry, rng: np.random.Generator, amplitude_mm: float = 3.0
) -> CableGeometry:
    """A true geometry within +-amplitude of the nominal one in each of the 12 parameters."""
    return CableGeometry.from_q(nominal.q + rng.uniform(-amplitude_mm, amplitude_mm, 12))


def simulate_observations(
    truth: MachineModel,
    nominal: MachineModel,
    poses: np.ndarray,
    *,
    noise_mm: float = 0.05,
    rng: np.random.Generator | None = None,
    t_s: np.ndarray | None = None,
    seconds_per_pose: float = 30.0,
) -> Observations:
    """Command ``poses`` (in visiting order) through ``nominal``; measure ``truth`` with noise."""
    rng = rng or np.random.default_rng()
    poses = np.asarray(poses, dtype=float)
    s_cmd, dirs = commanded_path(nominal, poses)
    times = (
        np.arange(1, len(poses) + 1) * seconds_per_pose if t_s is None else np.asarray(t_s, float)
    )
    actual = truth.fk(s_cmd, MotionContext(t_s=times, directions=dirs))
    measured = actual + rng.normal(0.0, noise_mm, actual.shape)
    return Observations(measured, s_cmd, times, dirs, noise_mm)


def achieved_points(
    truth: MachineModel, commanding: MachineModel, targets: np.ndarray
) -> np.ndarray:
    """Where the true machine puts the effector when ``commanding`` drives it to ``targets``
    (through integer steps, as on the real machine)."""
    steps = commanding.steps(commanding.ik(targets, path=True))
    return truth.fk(commanding.sliders_from_steps(steps))
