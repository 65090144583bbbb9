"""Hidden-effect session folders for end-to-end tests (simulator -> mocap files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdprhost.calibration.commanding import commanded_path
from cdprhost.effects.base import Effect, MotionContext
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times
from cdprhost.sim.synthetic_session import write_synthetic_session


def write_hidden_session(
    directory: Path,
    nominal: MachineModel,
    effect: str | Effect | None,
    seed: int,
    *,
    vector: np.ndarray | None = None,
    n_poses: int = 40,
    noise_mm: float = 0.05,
    format: str = "motive-csv",
    profile_name: str = "paper-simulation",
) -> MachineModel:
    """Simulate a session of a true machine with ``effect`` hidden; write it as mocap takes.

    Returns the true machine. The takes carry ``noise_mm`` per coordinate on the
    measured point (a static offset per take, plus a little frame jitter)."""
    rng = np.random.default_rng(seed)
    truth = hidden_truth(nominal, rng, effect, vector)
    poses = measurement_tour(nominal, n_poses, rng)
    t_s = session_times(n_poses, rng)
    s_cmd, dirs = commanded_path(nominal, poses)
    actual = truth.fk(s_cmd, MotionContext(t_s=t_s, directions=dirs))
    write_synthetic_session(
        directory,
        actual,
        poses,
        s_cmd,
        t_s,
        dirs.astype(int),
        profile_name,
        format=format,
        noise_mm=noise_mm,
        seed=seed + 7919,
    )
    return truth
