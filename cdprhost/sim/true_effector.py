"""Where the hidden true machine's effector is when the simulated device has settled.

The device reports absolute module steps and its time at each settle. The truth's
forward kinematics with its effects gives the point: backlash needs each module's last
direction of motion (passed by the device, read from its record of executed segments,
or else inferred from the change of steps since the previous settle), drift the time.
Shared by the virtual motion capture and the virtual camera.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.effects.base import MotionContext
from cdprhost.kinematics import MachineModel


class TrueEffector:
    """Tracks the true effector across settles (``settle``); ``point`` is the latest."""

    def __init__(self, truth: MachineModel):
        self.truth = truth
        self.dirs = np.ones(3)
        self.last_steps: np.ndarray | None = None
        self.point: np.ndarray | None = None
        self.time_s = 0.0
        self._record: Any = None

    def attach_record(self, record: Any) -> None:
        """Read last-motion directions from the device's (growing) record of executed segments
        (a ``SegmentRecord``: its ``steps(last=n)`` array, or a list of entries)."""
        self._record = record

    def record_directions(self, window: int = 4096) -> np.ndarray | None:
        if not self._record:
            return None
        if hasattr(self._record, "steps"):
            steps = self._record.steps(last=window)[:, :3]
        else:
            steps = np.array([e["steps"][:3] for e in self._record[-window:]], dtype=np.int64)
        moves = np.diff(steps, axis=0)
        dirs = self.dirs.copy()
        for k in range(3):  # three columns; the record window is vectorised
            nz = np.flatnonzero(moves[:, k])
            if nz.size:
                dirs[k] = np.sign(moves[nz[-1], k])
        return dirs

    def effector_point(
        self, steps: ArrayLike, device_time_s: float, directions: ArrayLike | None = None
    ) -> np.ndarray:
        """Where the true effector is for absolute module steps (the first three of ``steps``)."""
        n = np.asarray(steps, dtype=float)[:3]
        dirs = self.dirs if directions is None else np.asarray(directions, dtype=float)[:3]
        ctx = MotionContext(t_s=np.array([float(device_time_s)]), directions=dirs[None, :])
        return np.asarray(self.truth.fk(self.truth.sliders_from_steps(n)[None, :], ctx)[0])

    def settle(
        self, steps: ArrayLike, device_time_s: float, directions: ArrayLike | None = None
    ) -> np.ndarray:
        """Update the directions for a settle at ``steps`` and return the true point
        (NaN where the cables cannot meet)."""
        n = np.asarray(steps, dtype=np.int64)[:3]
        from_record = self.record_directions() if directions is None else None
        if from_record is not None:
            self.dirs = from_record
        elif self.last_steps is not None:
            moved = n - self.last_steps
            self.dirs = np.where(moved != 0, np.sign(moved), self.dirs)
        self.last_steps = n
        self.point = self.effector_point(n, device_time_s, directions)
        self.time_s = float(device_time_s)
        return self.point
