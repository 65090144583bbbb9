"""The machine as Klipper's ``winch`` kinematics sees it, and what that view leaves out.

Klipper's winch kinematics sets each stepper's position to the straight distance from
its anchor to the toolhead, ``|P - anchor_k|``, in the toolhead's (the G-code's) frame;
steps are that distance divided by ``rotation_distance / (full_steps * microsteps)``.
Our model commands ``s_k = (|B - A_k| - L_k0) / (1 + eps_k)`` (``drive_scale`` folded
in) with ``B = P + bed_origin``, so the two agree step for step when

- ``anchor_k = A_k - bed_origin`` (the outlets in the G-code frame),
- the step distance is ``(1 + eps_k) / steps_per_mm_k``,
- Klipper is told, once the sliders sit at their endstops, that the toolhead is at the
  home point (G-code frame): its stepper positions are then the cable lengths there,
  ``L_k0 + (1 + eps_k) home_mm_k``, as ours are.

Everything else the profile calibrated (cable stretch, backlash, drift, ...) has no
place in that config; :func:`dropped_effects` measures the position error each one
leaves over the workspace when Klipper drives the real machine.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

from cdprhost.effects.base import MotionContext
from cdprhost.effects.registry import EffectChain
from cdprhost.kinematics.geometry import cable_lengths
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.kinematics.machine import MachineModel

#: effects the winch config expresses exactly (folded into rotation_distance)
FOLDED = ("drive_scale",)
#: a drift is reported as the error it has built up after this long (s)
DRIFT_HORIZON_S = 3600.0


@dataclass(frozen=True)
class WinchEquivalent:
    """The numbers of a Klipper winch config for a profile."""

    anchors: np.ndarray  # (3, 3) outlets in the G-code frame (mm)
    step_distance: np.ndarray  # (3,) mm of cable per step, drive_scale folded in
    home: np.ndarray  # (3,) the home point in the G-code frame (mm)
    home_lengths: np.ndarray  # (3,) Klipper's stepper positions at home (mm of cable)
    home_steps: np.ndarray  # (3,) our absolute steps at home


@dataclass(frozen=True)
class DroppedEffect:
    """A calibrated effect the winch config cannot express, and what it costs."""

    name: str
    rms_mm: float  # position error over the workspace grid
    max_mm: float
    note: str  # under which assumption (backlash: worst direction; drift: after an hour)


def _folded(model: MachineModel) -> MachineModel:
    """The model with only the effects Klipper expresses."""
    keep = [(e.name, v) for e, v in zip(model.effects.effects, model.effects.vectors)]
    keep = [(n, v) for n, v in keep if n in FOLDED]
    return model.with_geometry(
        model.geometry, EffectChain.from_vectors([n for n, _ in keep], [v for _, v in keep])
    )


def _eps(model: MachineModel) -> np.ndarray:
    for effect, vec in zip(model.effects.effects, model.effects.vectors):
        if effect.name == "drive_scale":
            return np.asarray(vec, dtype=float)
    return np.zeros(3)


def winch_equivalent(
    model: MachineModel, bed_origin: np.ndarray, home_mm: np.ndarray
) -> WinchEquivalent:
    origin = np.asarray(bed_origin, dtype=float)
    home_sliders = np.asarray(home_mm, dtype=float)
    eps = _eps(model)
    home = model.home_point(home_sliders)
    return WinchEquivalent(
        anchors=model.geometry.outlets - origin,
        step_distance=(1.0 + eps) / model.steps_per_mm,
        home=home - origin,
        home_lengths=cable_lengths(home[None, :], model.geometry.outlets)[0],
        home_steps=home_sliders * model.steps_per_mm,
    )


def winch_steps(winch: WinchEquivalent, points: np.ndarray) -> np.ndarray:
    """Klipper's absolute step positions at ``points`` (G-code frame), unrounded (N, 3)."""
    lengths = cable_lengths(np.asarray(points, dtype=float), winch.anchors)
    return winch.home_steps + (lengths - winch.home_lengths) / winch.step_distance


def dropped_effects(
    model: MachineModel, bed_origin: np.ndarray, home_mm: np.ndarray
) -> list[DroppedEffect]:
    """Each effect Klipper cannot express, with the position error it leaves.

    Klipper, given the config exported for the machine, commands the steps of
    :func:`winch_steps` at every grid point; the real machine, predicted by the model
    with the effect, goes elsewhere. Each effect is measured alone (on top of the
    folded ones), with the config that the profile with only those effects exports.
    """
    folded = _folded(model)
    origin = np.asarray(bed_origin, dtype=float)
    points = workspace_grid(model)
    found = []
    for effect, vec in zip(model.effects.effects, model.effects.vectors):
        if effect.name in FOLDED:
            continue
        names = [*folded.effects.names, effect.name]
        vectors = [*folded.effects.vectors, vec]
        real = model.with_geometry(model.geometry, EffectChain.from_vectors(names, vectors))
        winch = winch_equivalent(real, origin, home_mm)
        commands = winch_steps(winch, points - origin) / model.steps_per_mm
        errors, note = _errors(real, points, commands, effect.name)
        found.append(
            DroppedEffect(
                effect.name, float(np.sqrt(np.mean(errors**2))), float(errors.max()), note
            )
        )
    return found


def _errors(
    real: MachineModel, points: np.ndarray, commands: np.ndarray, name: str
) -> tuple[np.ndarray, str]:
    n = len(points)
    if name == "backlash":
        worst = np.zeros(n)
        for signs in product((-1.0, 1.0), repeat=3):
            ctx = MotionContext(directions=np.tile(signs, (n, 1)))
            worst = np.maximum(worst, _distance(real.fk(commands, ctx), points))
        return worst, "worst direction of travel of each module"
    if name == "drift":
        ctx = MotionContext(t_s=np.full(n, DRIFT_HORIZON_S))
        return (
            _distance(real.fk(commands, ctx), points),
            f"after {DRIFT_HORIZON_S / 3600:g} h without re-homing",
        )
    return _distance(real.fk(commands), points), "over the workspace grid"


def _distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a - b, axis=1)
