"""What the host commands for a tour of poses: slider targets through the nominal model and
each module's approach direction (backlash needs it)."""

from __future__ import annotations

import numpy as np

from cdprhost.effects.backlash import path_directions
from cdprhost.kinematics.machine import MachineModel


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
