"""The calibration wizard's device through the printer service: the wizard (its planning,
the takes' judging, the fit) runs in the UI's process, its moves and the embedded
device's simulated world in the service's device session (wire ``visit``, ``observe``,
``capture``).

:class:`ServiceWizardDevice` is the wizard's device (``visit``: the service moves,
settles, and answers the steps and the device's clock; a faulted device or a running print
is refused there, nothing moved). :class:`ServiceCamera` is the simulated camera watching
the service's embedded device, as a capture: each picture is rendered in the service and
handed over as a file.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.service import wire


class Asker(Protocol):
    def ask(self, message: Any, timeout_s: float | None = None) -> Any: ...


def answered(service: Asker, message: Any) -> Any:
    """The service's answer to ``message``; CdprError with its reason when refused."""
    answer = service.ask(message)
    if answer is None:
        raise CdprError(f"the printer service did not answer {message.op}")
    if not answer.ok:
        raise CdprError(answer.error)
    return answer


class ServiceWizardDevice:
    """:class:`cdprhost.calibration.wizard.WizardDevice` in the service's device session."""

    def __init__(self, service: Asker, settle_s: float):
        self.service = service
        self.settle_s = float(settle_s)

    def visit(self, points: np.ndarray) -> tuple[np.ndarray, float]:
        rows = np.asarray(points, dtype=float).reshape(-1, 3)
        points_mm = tuple((float(p[0]), float(p[1]), float(p[2])) for p in rows)
        request = wire.Visit(points=points_mm, settle_s=self.settle_s)
        answer = answered(self.service, request)
        if answer.status is None or answer.device_time_s is None:
            raise CdprError("the printer service did not say where the device settled")
        return np.asarray(answer.status.steps[:3], dtype=np.int64), float(answer.device_time_s)


class ServiceCamera:
    """The simulated camera of the service's embedded device, with the part of
    ``cv2.VideoCapture``'s interface the wizard uses; each picture passes through a private
    temporary folder, removed once read."""

    def __init__(self, service: Asker, size: tuple[int, int]):
        self.service = service
        answered(service, wire.Observe(camera=size))

    def isOpened(self) -> bool:
        return True

    def read(self) -> tuple[bool, Any]:
        import cv2

        folder = Path(tempfile.mkdtemp(prefix="cdpr-camera-"))
        try:
            answer = answered(self.service, wire.Capture(folder=str(folder), frames=1))
            if len(answer.files) != 1 or Path(answer.files[0]).parent != folder:
                raise CdprError(f"the printer service wrote no picture into {folder}")
            image = cv2.imread(answer.files[0], cv2.IMREAD_COLOR)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        return image is not None, image

    def release(self) -> None:
        pass
