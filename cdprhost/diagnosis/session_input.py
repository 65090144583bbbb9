"""Session folder -> observations and noise estimate for the diagnosis (thin shell).

The noise may be declared in ``session.toml`` as ``[mocap] noise_mm`` or
``[session] noise_mm``; see :mod:`cdprhost.diagnosis.noise` for the fallbacks.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.session import SESSION_FILE, RejectedTake, load_session
from cdprhost.diagnosis.noise import NoiseEstimate, estimate_noise
from cdprhost.diagnosis.workflow import Diagnosis, DiagnosisSettings, diagnose
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel

NOISE_KEYS = (("mocap", "noise_mm"), ("session", "noise_mm"))


@dataclass(frozen=True)
class SessionData:
    directory: Path
    observations: Observations
    noise: NoiseEstimate
    pose_numbers: np.ndarray  # (K,) poses.csv numbers of the accepted poses
    rejected: tuple[RejectedTake, ...]
    profile_ref: str  # the profile that commanded the poses (from session.toml)


def declared_noise(directory: Path) -> float | None:
    """``noise_mm`` from session.toml, validated; None when not declared."""
    path = directory / SESSION_FILE
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None  # load_session reports these properly
    for table, key in NOISE_KEYS:
        value = data.get(table, {}).get(key) if isinstance(data.get(table), dict) else None
        if value is None:
            continue
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value <= 0
        ):
            raise InputError(
                f"{table}.{key}: must be a positive number of millimetres, got {value!r}",
                source=str(path),
            )
        return float(value)
    return None


def load_session_data(
    directory: str | os.PathLike[str], steps_per_mm: np.ndarray | float = 400.0
) -> SessionData:
    """Measure every take of a session folder; rejected takes are listed, not used."""
    root = Path(directory)
    session = load_session(root)
    declared = declared_noise(root)
    m = session.measure()
    if len(m) == 0:
        raise InputError(
            "no usable take in the session"
            + (f" ({len(m.rejected)} rejected)" if m.rejected else ""),
            source=str(root),
            problems=[r.message for r in m.rejected[:10]],
        )
    noise = estimate_noise(
        declared, sliders=m.s_cmd, measured=m.measured, steps_per_mm=steps_per_mm, take_std_mm=m.std
    )
    obs = Observations(m.measured, m.s_cmd, m.t_s, m.dirs.astype(float), noise.sigma_mm)
    return SessionData(root, obs, noise, m.pose, m.rejected, session.config.session.profile)


def diagnose_session(
    directory: str | os.PathLike[str],
    model: MachineModel,
    settings: DiagnosisSettings | None = None,
) -> tuple[Diagnosis, SessionData]:
    """Load a session folder and run the workflow on it (for the CLI and the TUI backend)."""
    data = load_session_data(directory, model.steps_per_mm)
    return diagnose(data.observations, model, data.noise, settings or DiagnosisSettings()), data
