"""The simulated world around the service's embedded device, for the calibration wizard of
a client: what watches the device (the virtual motion capture of a hidden true machine, or
the simulated camera) and the camera's pictures.

The embedded simulated device lives in the service's process, so its observers live here
too: the device calls an observer's ``on_settled`` whenever it comes to rest, the virtual
motion capture then writes a take into the client's folder, and the simulated camera
renders what it sees when asked (``capture``), written as PNG files for the client to read.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from cdprhost.errors import CdprError, InputError
from cdprhost.service import wire

NOT_EMBEDDED = (
    "the simulated observers watch the embedded simulated device only (a sim-device on a "
    "pty takes --truth and --mocap-dir itself)"
)


def make_observer(request: wire.Observe, model: Any) -> Any:
    """The observer ``request`` names (None: nothing watches); InputError for a bad one.
    The simulated camera watches the nominal machine ``model``."""
    if request.camera is not None:
        if request.truth is not None or request.mocap_dir is not None:
            raise InputError("observe: the camera or the virtual motion capture, not both")
        from cdprhost.sim.camera.device import VirtualCamera
        from cdprhost.sim.camera.scene import rig_for_size

        return VirtualCamera(model, rig_for_size(request.camera))
    if request.truth is None and request.mocap_dir is None:
        return None
    if request.mocap_dir is not None and not os.path.isabs(request.mocap_dir):
        raise InputError(f"observe: mocap_dir {request.mocap_dir!r} is not an absolute path")
    from cdprhost.sim.virtual_mocap import make_observer as virtual_mocap

    return virtual_mocap(request.truth, request.mocap_dir)


def watch(device: Any, observer: Any) -> None:
    """Put ``observer`` on the embedded simulated device (replacing the one it had): it is
    told of every settle from now on, and reads the directions of motion from the device's
    record (the truth's backlash)."""
    device.observer = observer  # kept across the device's reboots
    device.machine.observer = observer  # the running boot's motion model
    attach = getattr(observer, "attach_record", None)
    if attach is not None:
        attach(device.record)


def capture(camera: Any, folder: str, frames: int) -> tuple[str, ...]:
    """``frames`` pictures of the simulated camera now, written as PNG into ``folder``
    (created); the files, in order."""
    import cv2

    if not os.path.isabs(folder):
        raise InputError(f"capture: folder {folder!r} is not an absolute path")
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for _ in range(frames):
        ok, image = camera.read()
        if not ok or image is None:
            raise CdprError("the simulated camera gave no picture")
        fd, name = tempfile.mkstemp(prefix="frame-", suffix=".png", dir=out)
        os.close(fd)
        if not cv2.imwrite(name, image, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
            raise CdprError(f"could not write the picture {name}")
        files.append(name)
    return tuple(files)
