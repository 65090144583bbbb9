"""A session folder identified: its takes measured by whichever source it declares
(motion capture, :mod:`.takes`; a camera, :mod:`.camera.session`), then the geometry
identified from those observations (:mod:`.identification`).

The one place that knows both the sources and the identification: identification takes
observations and imports no source, and no source imports this module.
"""

from __future__ import annotations

import dataclasses
import os

from cdprhost.calibration.camera.session import measure_camera_session
from cdprhost.calibration.identification import Identification, identify_verified
from cdprhost.calibration.measurements import SessionMeasurements
from cdprhost.calibration.session import Session, load_session
from cdprhost.calibration.trust import DEFAULT_TRUST, TrustLimits
from cdprhost.calibration.verification import DEFAULT_ALPHA
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel


def identify_session(
    directory: str | os.PathLike[str] | Session,
    base: MachineModel,
    *,
    noise_floor_mm: float | None = None,
    limits: TrustLimits = DEFAULT_TRUST,
    refine: bool = True,
    alpha: float = DEFAULT_ALPHA,
) -> Identification:
    """Measure every take of a session folder and identify (refused takes are listed, not
    used): verify on the check poses, then refine on all poses (:func:`identify_verified`).

    Each pose's noise is its take's standard error (:mod:`.pose_noise`); ``noise_floor_mm``
    adds a part no take shows (default: ``noise_mm`` of session.toml, if declared)."""
    session = directory if isinstance(directory, Session) else load_session(directory)
    meas = measure_any(session, base)
    if len(meas) == 0:
        raise InputError(
            "no usable take in the session",
            source=str(session.directory),
            problems=[str(r) for r in meas.rejected],
        )
    noise = meas.noise(base.steps_per_mm, floor_mm=noise_floor_mm)
    notes = (
        tuple(session.warnings) + ((noise.note,) if noise.extra_mm > 0 else ()) + tuple(meas.notes)
    )
    result = identify_verified(
        meas.observations(noise),
        base,
        meas.roles,
        refine=refine,
        alpha=alpha,
        rejected=tuple(str(r) for r in meas.rejected),
        limits=limits,
        noise=noise,
        pose_numbers=meas.pose,
        notes=notes,
    )
    if meas.refusals and result.trust is not None:
        trust = dataclasses.replace(result.trust, refusals=result.trust.refusals + meas.refusals)
        result = dataclasses.replace(result, trust=trust)
    return result


def measure_any(
    session: Session, base: MachineModel, *, refine: bool = True
) -> SessionMeasurements:
    """A session's measurements: motion-capture takes, or a camera session's pictures (with
    ``refine``, the camera refined against ``base``'s commanded motion,
    :mod:`.camera.session`)."""
    camera = session.config.camera
    if camera is not None:
        return measure_camera_session(
            session.directory,
            camera,
            session.poses,
            session.take_paths,
            base,
            declared_noise_mm=session.config.declared_noise_mm,
            refine=refine,
        )
    return session.measure()
