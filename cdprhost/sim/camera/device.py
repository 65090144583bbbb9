"""The simulated camera beside the simulated device, for the wizard (``--camera sim``).

:class:`VirtualCamera` is both an observer of the embedded device (``on_settled``: the
hidden true machine's effector position, :class:`~cdprhost.sim.true_effector.TrueEffector`)
and a capture with the part of ``cv2.VideoCapture``'s interface the wizard uses
(``isOpened``, ``read``, ``release``): every ``read`` renders what the rig's camera sees
now, with fresh noise, compressed and decoded as a webcam's MJPEG stream is.
``blurred_settles`` (settle numbers from 1) are seen through heavy motion blur, as when
the machine still shakes: the wizard must refuse those takes and capture again.
"""

from __future__ import annotations

import threading
from collections.abc import Collection
from dataclasses import replace
from typing import Any

import numpy as np

from cdprhost.kinematics import MachineModel
from cdprhost.sim.camera.imaging import decode
from cdprhost.sim.camera.scene import CameraRig
from cdprhost.sim.true_effector import TrueEffector

SHAKE_PX = 25.0  # motion smear of a blurred settle


class VirtualCamera:
    def __init__(
        self,
        truth: MachineModel,
        rig: CameraRig,
        *,
        supersample: int = 2,
        jitter_mm: float = 0.003,
        blurred_settles: Collection[int] = (),
        seed: int = 0,
    ):
        self.truth = truth
        self.rig = rig
        self.tracker = TrueEffector(truth)
        self.renderer = rig.renderer(supersample, seed)
        self.jitter_mm = float(jitter_mm)
        self.blurred_settles = frozenset(int(n) for n in blurred_settles)
        self.settles = 0
        self.frames_read = 0
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._home = np.asarray(truth.fk(np.zeros((1, 3)))[0])

    # ------------------------------------------------------------ the device's observer
    def attach_record(self, record: Any) -> None:
        self.tracker.attach_record(record)

    def on_settled(self, steps: Any, device_time_s: float, directions: Any | None = None) -> None:
        with self._lock:
            self.tracker.settle(steps, device_time_s, directions)
            self.settles += 1

    # ------------------------------------------------------------ the capture
    @property
    def true_point(self) -> np.ndarray:
        point = self.tracker.point
        return self._home if point is None else point

    def isOpened(self) -> bool:
        return True

    def read(self) -> tuple[bool, np.ndarray]:
        with self._lock:
            rig = self.rig
            if self.settles in self.blurred_settles:
                rig = replace(rig, imaging=replace(rig.imaging, motion_px=SHAKE_PX))
            b = self.true_point + self._rng.normal(0.0, self.jitter_mm, 3)
            image = decode(rig.frame(self.renderer, b, self._rng))
            self.frames_read += 1
        return True, image

    def release(self) -> None:
        pass


class ViewsCapture:
    """A simulated user waving the calibration board before the rig's camera: ``read``
    gives rendered calibration views one after the other (then again from the first)."""

    def __init__(self, rig: CameraRig, n_views: int = 18, seed: int = 0, supersample: int = 2):
        from cdprhost.sim.camera.views import render_views

        self._views = render_views(
            rig.camera, rig.imaging, n_views=n_views, seed=seed, supersample=supersample
        )
        self._next = 0

    def isOpened(self) -> bool:
        return True

    def read(self) -> tuple[bool, np.ndarray]:
        image = decode(self._views[self._next % len(self._views)])
        self._next += 1
        return True, image

    def release(self) -> None:
        pass
