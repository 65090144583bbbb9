"""Starting a motion-capture session from scratch (no folder, no TOML), for screens and
scripts.

A screen asks the user for one take recorded with the motion-capture software
(:func:`markers_in_take` lists its markers, :func:`suggest_roles` guesses which are on the
base and which on the effector), for the base markers' positions in the base frame and the
effector offset, builds the ``[mocap]`` configuration with :func:`mocap_config` (every
problem listed at once, as lines a screen can show) and hands it to
:class:`~cdprhost.calibration.wizard.CalibrationWizard`, which creates the folder
(:func:`~cdprhost.calibration.session.mocap_for_session` picks the configuration a wizard
starts or resumes with).
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from typing import Any

from pydantic import ValidationError

from cdprhost.calibration.config_input import validation_problems
from cdprhost.calibration.mocap.readers import read_take
from cdprhost.calibration.mocap.takes import MocapConfig
from cdprhost.errors import InputError

BASE_WORDS = ("base", "frame", "ground", "floor", "fixed")
EFFECTOR_WORDS = ("ee", "effector", "end", "head", "nozzle", "tool", "platform")


def markers_in_take(path: str | os.PathLike[str], format: str | None = None) -> tuple[str, ...]:
    """Marker names of a take file (any supported format, detected from the content)."""
    return read_take(path, format).marker_names


def _words(name: str) -> list[str]:
    return [w for w in re.split(r"[^a-z0-9]+", name.lower()) if w]


def suggest_roles(names: Sequence[str]) -> tuple[list[str], list[str]]:
    """(base markers, effector markers) guessed from the names (``Base:F1``, ``EE:E2``...);
    names that say neither are left out for the user to place."""
    base = [n for n in names if any(w.startswith(BASE_WORDS) for w in _words(n))]
    eff = [
        n for n in names if n not in base and any(w.startswith(EFFECTOR_WORDS) for w in _words(n))
    ]
    return base, eff


def mocap_config(
    base_markers: Mapping[str, Sequence[float]],
    effector_markers: Sequence[str],
    offset: Sequence[float] = (0.0, 0.0, 0.0),
    *,
    format: str | None = None,
    acceptance: Mapping[str, Any] | None = None,
    noise_mm: float | None = None,
) -> MocapConfig:
    """The ``[mocap]`` configuration, validated; :class:`InputError` lists every problem."""
    data: dict[str, Any] = {
        "format": format,
        "base_markers": {k: tuple(v) for k, v in base_markers.items()},
        "effector": {"markers": tuple(effector_markers), "offset": tuple(offset)},
        "acceptance": dict(acceptance or {}),
        "noise_mm": noise_mm,
    }
    try:
        return MocapConfig.model_validate(data)
    except ValidationError as exc:
        raise InputError(
            "invalid motion-capture configuration", problems=validation_problems(exc)
        ) from None
