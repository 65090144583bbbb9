"""A camera as the calibration wizard's measuring source, as both front ends offer it
(`calibrate wizard --camera` and the calibrate screen): the simulated camera's picture size
(bounded before anything is drawn), and the camera's takes and the candidate poses it sees."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdprhost.errors import InputError

SIM_PICTURE_MIN = (320, 240)
SIM_PICTURE_MAX = (3840, 2160)  # 4K UHD: rendering costs memory and time by the pixel


def picture_size(text: str) -> tuple[int, int] | None:
    """``WxH`` (e.g. ``1920x1080``) as (width, height); None when ``text`` is not of that form
    (the size is not checked: :func:`picture_size_problem`)."""
    m = re.fullmatch(r"\s*(\d{1,6})\s*[xX]\s*(\d{1,6})\s*", text)
    return None if m is None else (int(m[1]), int(m[2]))


def picture_size_problem(text: str) -> str | None:
    """Why ``text`` cannot be the simulated camera's picture size, or None."""
    size = picture_size(text)
    if size is None:
        return f"expected WxH (e.g. 1920x1080), got {text!r}"
    (w0, h0), (w1, h1) = SIM_PICTURE_MIN, SIM_PICTURE_MAX
    w, h = size
    if not (w0 <= w <= w1 and h0 <= h <= h1):
        return f"{w}x{h} is outside {w0}x{h0} to {w1}x{h1} (a simulated picture that size)"
    return None


@dataclass
class WizardCamera:
    """The capture, the session's [camera] configuration and the camera's intrinsics; with
    the simulated camera, ``observer`` watches the simulated device."""

    capture: Any
    config: Any  # CameraConfig
    intrinsics: Any  # Intrinsics
    observer: Any = None

    def takes(self, session: Path, frames: int, log: Callable[[str], None]) -> Any:
        from cdprhost.calibration.camera.capture import CameraTakes

        return CameraTakes(
            self.capture,
            session / "captures",
            self.config.setup(),
            self.intrinsics,
            frames,
            log=log,
        )

    def candidates(
        self, takes: Any, model: Any, needed: int, log: Callable[[str], None] | None = None
    ) -> Any:
        """The planner's candidate poses the camera sees well (from a first look); ``log``
        is told how many of them."""
        from cdprhost.calibration.camera.visibility import visible_mask
        from cdprhost.calibration.planning import candidate_poses

        view = takes.first_look()
        cand = candidate_poses(model)
        keep = cand[visible_mask(cand, view, self.config.setup())]
        if log is not None:
            log(f"camera: {len(keep)} of {len(cand)} candidate poses are in good view")
        if len(keep) < needed:
            raise InputError(
                f"the camera sees the effector board well at only {len(keep)} candidate poses "
                f"({needed} needed): move the camera back or tilt the effector board toward it"
            )
        return keep
