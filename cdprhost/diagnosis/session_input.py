"""Session folder -> observations for the diagnosis (thin shell over the one session reader).

The folder is read by :func:`cdprhost.calibration.session.load_session`, its takes
measured and judged together, and the observations built with each pose's noise by
:meth:`~cdprhost.calibration.session.SessionMeasurements.observations` (the same builder
and noise model identification uses).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.measurements import RejectedTake
from cdprhost.calibration.pose_noise import PoseNoise
from cdprhost.calibration.session import load_session
from cdprhost.calibration.session_identification import measure_any
from cdprhost.diagnosis.workflow import Diagnosis, DiagnosisSettings, diagnose
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel


@dataclass(frozen=True)
class SessionData:
    directory: Path
    observations: Observations
    noise: PoseNoise
    pose_numbers: np.ndarray  # (K,) poses.csv numbers of the accepted poses
    rejected: tuple[RejectedTake, ...]
    profile_ref: str  # the profile that commanded the poses (from session.toml)
    warnings: tuple[str, ...] = ()


def load_session_data(
    directory: str | os.PathLike[str],
    steps_per_mm: np.ndarray | float = 400.0,
    model: MachineModel | None = None,
) -> SessionData:
    """Measure every take of a session folder; refused takes are listed, not used."""
    root = Path(directory)
    session = load_session(root)
    # a camera is not refined against the motion here: against the plain model it would
    # take the very effect sought for a lens error (the session-level camera fit still holds)
    m = measure_any(session, model, refine=False) if model is not None else session.measure()
    if len(m) == 0:
        raise InputError(
            "no usable take in the session"
            + (f" ({len(m.rejected)} refused)" if m.rejected else ""),
            source=str(root),
            problems=[str(r) for r in m.rejected[:10]],
        )
    noise = m.noise(steps_per_mm)
    return SessionData(
        root,
        m.observations(noise),
        noise,
        m.pose,
        m.rejected,
        session.config.session.profile,
        tuple(session.warnings),
    )


def diagnose_session(
    directory: str | os.PathLike[str],
    model: MachineModel,
    settings: DiagnosisSettings | None = None,
) -> tuple[Diagnosis, SessionData]:
    """Load a session folder and run the workflow on it (for the CLI and the TUI backend)."""
    data = load_session_data(directory, model.steps_per_mm, model)
    return diagnose(data.observations, model, data.noise, settings or DiagnosisSettings()), data
