"""Hidden-effect session folders for end-to-end tests (simulator -> realistic mocap files)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cdprhost.effects.base import Effect
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.mocap_noise import MocapNoise
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times
from cdprhost.sim.synthetic_session import write_measured_session

#: The motion capture of these sessions: 0.2 mm autocorrelated jitter per marker, effector
#: hum, settling swings, runs of gaps (3 % of cells).
SESSION_MOCAP = MocapNoise(
    jitter_mm=0.2,
    correlation_s=0.02,
    marker_variation=0.3,
    hum_mm=0.02,
    settle_mm=0.4,
    settle_hz=3.0,
    settle_decay_s=0.2,
    gap_fraction=0.03,
    gap_run_frames=10.0,
)


def write_hidden_session(
    directory: Path,
    nominal: MachineModel,
    effect: str | Effect | Sequence[str | Effect] | None,
    seed: int,
    *,
    vector: np.ndarray | None = None,
    n_poses: int = 40,
    format: str = "motive-csv",
    profile_name: str = "paper-simulation",
    rate_hz: float = 120.0,
    duration_s: float = 2.0,
    realism: MocapNoise = SESSION_MOCAP,
) -> MachineModel:
    """Simulate a session of a true machine with ``effect`` hidden (one, several or none);
    write it as realistic mocap takes. Returns the true machine."""
    rng = np.random.default_rng(seed)
    truth = hidden_truth(nominal, rng, effect, vector)
    poses = measurement_tour(nominal, n_poses, rng)
    write_measured_session(
        directory,
        truth,
        nominal,
        poses,
        session_times(n_poses, rng),
        realism=realism,
        rate_hz=rate_hz,
        duration_s=duration_s,
        format=format,
        profile_name=profile_name,
        seed=seed + 7919,
    )
    return truth
