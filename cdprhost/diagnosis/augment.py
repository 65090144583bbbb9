"""The augmented profile: the input profile with the diagnosis' final model in it.

Geometry = the 12 parameters refitted together with the effects; ``[effects]``
gets each added effect's table (values and standard errors); ``[calibration]``
records the diagnosis (verdict, 95 % intervals, held-out errors) so the profile
says where its numbers came from. IK and FK read ``[effects]``, so printing with
this profile compensates the named effects. An effect the profile already had
whose refitted parameters are no longer physical (e.g. EA <= 0) is dropped, and
the record says so.
"""

from __future__ import annotations

from typing import Any

from cdprhost.diagnosis.effect_values import admissible
from cdprhost.diagnosis.workflow import Diagnosis
from cdprhost.jsonsafe import json_safe
from cdprhost.profile.models import MachineProfile


def _toml_intervals(ci: dict[str, Any]) -> dict[str, Any]:
    """TOML has no null: an unbounded interval end becomes the string "inf"."""

    def fix(v: Any) -> Any:
        if isinstance(v, list):
            return [fix(x) for x in v]
        return "inf" if v is None else v

    return {k: fix(v) for k, v in ci.items()}


def augmented_profile(
    profile: MachineProfile, diagnosis: Diagnosis, *, session: str = ""
) -> MachineProfile:
    """A copy of ``profile`` carrying the diagnosis' final model (see module docstring)."""
    fit = diagnosis.final.fit
    q = fit.x_[:12]
    effects, dropped = {}, []
    for name in diagnosis.final.effects:
        if admissible(fit, name):
            effects[name] = json_safe(diagnosis.parameters[name]["table"], drop_none=True)
        else:
            dropped.append(name)
    record = {
        "source": "cdprhost diagnose",
        "session": session,
        "verdict": diagnosis.verdict,
        "effects_added": list(diagnosis.effects),
        "heldout_rms_before_mm": diagnosis.base.heldout_rms_mm,
        "heldout_rms_after_mm": diagnosis.final.heldout_rms_mm,
        "noise_floor_mm": diagnosis.noise_floor_mm,
        "noise_mm": diagnosis.noise.typical_mm,
        "noise_source": diagnosis.noise.source,
        "poses": diagnosis.n_poses,
        "ci95": {
            n: _toml_intervals(json_safe(diagnosis.parameters[n]["ci95"], drop_none=True))
            for n in diagnosis.final.effects
        },
    }
    if dropped:
        record["dropped"] = [f"{n}: fitted parameters are not physical" for n in dropped]
    if diagnosis.verdict != "named" and diagnosis.effects:
        record["note"] = f"verdict {diagnosis.verdict}: effects added are tentative"
    calibration = dict(profile.calibration)
    calibration["diagnosis"] = json_safe(record, drop_none=True)
    return profile.with_geometry(
        q[:9].reshape(3, 3), q[9:12], effects=effects, calibration=calibration
    )
