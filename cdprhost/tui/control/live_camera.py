"""A camera instead of motion capture for the calibrate screen (what `calibrate wizard --camera`
does, on the same core functions): the capture, the session's [camera] boards, the
intrinsics, the poses the camera sees, and a take source that takes the pictures.

``source``: a device index, a video or URL OpenCV opens, or ``sim`` / ``sim:WxH`` (the
simulated camera watching the embedded simulated device; it then observes that device).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdprhost.errors import InputError

#: the simulated camera's picture size on the screen unless given (smaller: quicker pictures,
#: bigger boards)
SIM_SIZE = (1280, 720)
SIM_MIN = (320, 240)
SIM_MAX = (3840, 2160)
FRAMES = 5  # pictures per take, as the wizard's default


def sim_size(source: str) -> tuple[int, int] | None:
    """The simulated camera's size for ``sim`` / ``sim:WxH`` (None: not the simulated one);
    InputError for a size out of bounds."""
    text = source.strip().lower()
    if text == "sim":
        return SIM_SIZE
    m = re.fullmatch(r"sim:(\d{1,6})x(\d{1,6})", text)
    if not m:
        if text.startswith("sim"):
            raise InputError(f"camera {source!r}: sim or sim:WxH (e.g. sim:1280x720)")
        return None
    w, h = int(m[1]), int(m[2])
    if not (SIM_MIN[0] <= w <= SIM_MAX[0] and SIM_MIN[1] <= h <= SIM_MAX[1]):
        raise InputError(
            f"camera {source!r}: {w}x{h} is outside {SIM_MIN[0]}x{SIM_MIN[1]} to "
            f"{SIM_MAX[0]}x{SIM_MAX[1]}"
        )
    return w, h


def camera_table(path: Path) -> Any:
    """The ``[camera]`` table of a TOML file (a session.toml or just that table)."""
    from pydantic import ValidationError

    from cdprhost.calibration.camera.config import CameraConfig
    from cdprhost.calibration.config_input import read_toml, validation_problems

    data = read_toml(path)
    if "camera" not in data:
        raise InputError("no [camera] table (the boards of camera-session.md)", source=str(path))
    try:
        return CameraConfig.model_validate(data["camera"])
    except ValidationError as exc:
        raise InputError(
            "invalid [camera] table", source=str(path), problems=validation_problems(exc, "camera")
        ) from None


@dataclass
class CameraSetup:
    capture: Any
    config: Any  # CameraConfig
    intrinsics: Any  # Intrinsics
    source: str

    def takes(self, session: Path, log: Callable[[str], None], frames: int = FRAMES) -> Any:
        from cdprhost.calibration.camera.capture import CameraTakes

        return CameraTakes(
            self.capture,
            session / "captures",
            self.config.setup(),
            self.intrinsics,
            frames,
            log=log,
        )

    def candidates(self, takes: Any, model: Any, needed: int) -> Any:
        """The planner's candidate poses the camera sees well (from a first look)."""
        from cdprhost.calibration.camera.visibility import visible_mask
        from cdprhost.calibration.planning import candidate_poses

        view = takes.first_look()
        cand = candidate_poses(model)
        keep = cand[visible_mask(cand, view, self.config.setup())]
        if len(keep) < needed:
            raise InputError(
                f"the camera sees the effector board well at only {len(keep)} candidate poses "
                f"({needed} needed): move the camera back or tilt the effector board toward it"
            )
        return keep


def camera_setup(
    source: str,
    session: Path,
    model: Any,
    *,
    sim_camera: Callable[[tuple[int, int]], Any] | None = None,
    config_path: str | None = None,
    intrinsics_path: str | None = None,
    log: Callable[[str], None] = lambda _: None,
) -> CameraSetup:
    """The capture, [camera] configuration and intrinsics for ``source``; ``sim_camera``:
    the simulated camera of a size, watching the embedded simulated device (None: no such
    device)."""
    from cdprhost.calibration.camera.config import load_intrinsics
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
        config = camera_table(Path(config_path))
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
    return CameraSetup(capture, config, intrinsics, source)
