"""A camera instead of motion capture for the calibrate screen (what `calibrate wizard --camera`
does, on the same core functions): the capture, the session's [camera] boards, the
intrinsics, the poses the camera sees, and a take source that takes the pictures.

``source``: a device index, a video or URL OpenCV opens, or ``sim`` / ``sim:WxH`` (the
simulated camera watching the embedded simulated device; it then observes that device).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from cdprhost.calibration.camera.wizard_camera import (
    WizardCamera,
    picture_size,
    picture_size_problem,
)
from cdprhost.errors import InputError

#: the simulated camera's picture size on the screen unless given (smaller: quicker pictures,
#: bigger boards)
SIM_SIZE = (1280, 720)
FRAMES = 5  # pictures per take, as the wizard's default


def sim_size(source: str) -> tuple[int, int] | None:
    """The simulated camera's size for ``sim`` / ``sim:WxH`` (None: not the simulated one);
    InputError for a size out of bounds."""
    text = source.strip().lower()
    if text == "sim":
        return SIM_SIZE
    if not text.startswith("sim"):
        return None
    size = picture_size(text[4:]) if text.startswith("sim:") else None
    if size is None:
        raise InputError(f"camera {source!r}: sim or sim:WxH (e.g. sim:1280x720)")
    problem = picture_size_problem(text[4:])
    if problem:
        raise InputError(f"camera {source!r}: {problem}")
    return size


def camera_setup(
    source: str,
    session: Path,
    model: Any,
    *,
    sim_camera: Callable[[tuple[int, int]], Any] | None = None,
    config_path: str | None = None,
    intrinsics_path: str | None = None,
    log: Callable[[str], None] = lambda _: None,
) -> WizardCamera:
    """The capture, [camera] configuration and intrinsics for ``source``; ``sim_camera``:
    the simulated camera of a size, watching the embedded simulated device (None: no such
    device)."""
    from cdprhost.calibration.camera.config import load_camera_config, load_intrinsics
    from cdprhost.calibration.camera.takes import session_intrinsics
    from cdprhost.calibration.session import SESSION_FILE, load_session_config

    size = sim_size(source)
    rig: Any = None
    if size is not None:
        from cdprhost.sim.camera.scene import rig_for_size

        if sim_camera is None:
            raise InputError(
                "camera sim watches the embedded simulated device: connect to it first"
            )
        rig = rig_for_size(size)
        capture: Any = sim_camera(size)
    else:
        from cdprhost.calibration.camera.capture import open_capture

        capture = open_capture(source)
    if (session / SESSION_FILE).is_file():
        config = load_session_config(session / SESSION_FILE).camera
        if config is None:
            raise InputError(
                "this session measures with motion capture, not a camera", source=str(session)
            )
    elif config_path:
        config = load_camera_config(config_path)
    elif rig is not None:
        from cdprhost.sim.camera.session import camera_config

        config = camera_config(rig)
    else:
        raise InputError(
            "a new camera session needs its boards: name a session.toml with a [camera] table "
            "in the markers field"
        )
    if intrinsics_path:
        intrinsics = load_intrinsics(intrinsics_path)
    elif (session / SESSION_FILE).is_file():
        intrinsics = session_intrinsics(session, config)[0]
    elif rig is not None:
        from cdprhost.sim.camera.session import calibrated_intrinsics

        log("simulated camera: calibrating its intrinsics from rendered views")
        result = calibrated_intrinsics(rig)
        if not result.ok:  # pragma: no cover - the rendered views cover the image
            raise InputError("; ".join(result.problems))
        intrinsics = result.intrinsics
    else:
        raise InputError(
            "a camera needs its intrinsics: name its camera.toml (from `cdprhost calibrate "
            "camera`) in the intrinsics field"
        )
    return WizardCamera(capture, config, intrinsics)
