"""Simulated measurement sessions at the array level (no files).

A *true* machine (geometry and effects the host does not know) is commanded
through a *nominal* model: the host computes slider targets with the nominal IK,
the true machine goes wherever those targets really put it, and motion capture
measures that point with noise. Used by the calibration benchmark, the diagnosis
tests, and (through the take writers) the virtual motion capture.
"""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.fitting import Observations
from cdprhost.effects.backlash import path_directions
from cdprhost.effects.base import MotionContext
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel


def perturbed_geometry(
    nominal: CableGeometry, rng: np.random.Generator, amplitude_mm: float = 3.0
) -> CableGeometry:
    """A true geometry within +-amplitude of the nominal one in each of the 12 parameters."""
    return CableGeometry.from_q(nominal.q + rng.uniform(-amplitude_mm, amplitude_mm, 12))


def commanded_path(
    nominal: MachineModel, poses: np.ndarray, start_sliders: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Slider targets for poses visited in order, and each module's approach direction."""
    s_cmd = nominal.ik(poses)
    start = (
        np.zeros((1, 3))
        if start_sliders is None
        else np.asarray(start_sliders, float).reshape(1, 3)
    )
    dirs = path_directions(np.vstack([start, s_cmd]))[1:]
    return s_cmd, dirs


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


def validation_grid(
    model: MachineModel,
    heights: tuple[float, ...] = (120.0, 170.0, 220.0, 270.0, 320.0),
    spacing_mm: float = 15.0,
) -> np.ndarray:
    """Points of the build volume (inside every workspace rule) on a grid at several heights."""
    side = model.limits.build_side
    xs = np.arange(-side / 2, side / 2 + 1e-9, spacing_mm)
    ys = np.arange(-side / np.sqrt(3) / 2, side / np.sqrt(3) + 1e-9, spacing_mm)
    gx, gy, gz = np.meshgrid(xs, ys, np.asarray(heights, float), indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    return pts[model.check(pts).ok]
