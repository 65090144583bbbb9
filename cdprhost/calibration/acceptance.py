"""When a take is believed: the thresholds (``[mocap.acceptance]`` of session.toml) and the
verdict on a take's statistics.

The defaults follow from statistics, not from any one mocap system: a take is refused for
drift only when the drift is both significant (the Wald test of the fitted slope at
``drift_alpha``, with the noise's correlation accounted for) and physically relevant
(more than ``max_drift_mm`` over the take), so noisy systems do not lose sound takes and
quiet systems do not keep creeping ones. Spread and missing frames have plain caps. A
settling transient at the start is trimmed (up to ``max_settling_fraction`` of the take),
never a reason to refuse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.calibration.take_statistics import TakeStatistics

#: Reasons a take is refused (the ``<reason>`` of ``pose <id> (<take>): <reason>: <message>``).
REASONS = (
    "missing-marker",
    "base-fit",
    "gaps",
    "too-few-frames",
    "outliers",
    "spread",
    "drift",
    "wrong-pose",
    "unreadable",
)


class AcceptanceLimits(BaseModel):
    """``[mocap.acceptance]``; every key optional. Unknown keys are kept and reported
    (``unknown_keys``), not refused, so a folder written by another tool still reads."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)

    drift_alpha: float = Field(
        default=0.001, gt=0, lt=1, description="significance of the drift test"
    )
    max_drift_mm: float = Field(
        default=0.05, ge=0, description="smallest drift over a take that matters"
    )
    motion_alpha: float = Field(
        default=0.05,
        gt=0,
        lt=1,
        description="a kept take whose drift is significant at this level carries its motion "
        "(RMS of the ramp, drift / sqrt(12)) in its standard error",
    )
    max_spread_mm: float = Field(
        default=1.0, gt=0, description="cap on the RMS distance of frames from the centre"
    )
    min_valid_fraction: float = Field(
        default=0.5, gt=0, le=1, description="frames with the effector seen"
    )
    min_frames: int = Field(default=10, ge=3)
    outlier_mads: float = Field(default=5.0, gt=0)
    max_outlier_fraction: float = Field(default=0.25, ge=0, lt=1)
    max_settling_fraction: float = Field(default=0.5, ge=0, lt=1)
    settle_alpha: float = Field(default=0.01, gt=0, lt=1)
    max_base_rms_mm: float = Field(
        default=0.5, gt=0, description="base markers' misfit to session.toml"
    )
    min_scale_mm: float = Field(
        default=0.005, gt=0, description="floor of the noise scale (quantised exports)"
    )

    @property
    def unknown_keys(self) -> list[str]:
        return sorted(self.model_extra or {})


@dataclass(frozen=True)
class Verdict:
    """``reason`` None: the take is sound."""

    reason: str | None
    message: str


def judge(s: TakeStatistics, lim: AcceptanceLimits) -> Verdict:
    """The verdict on one take's statistics (first failing check, with its numbers)."""
    total, valid, used = int(s.n_frames), int(s.n_valid), int(s.n_used)
    if valid < lim.min_valid_fraction * total:
        return Verdict(
            "gaps",
            f"the effector is seen in only {valid} of {total} frames ({valid / max(total, 1):.0%}; "
            f"need {lim.min_valid_fraction:.0%})",
        )
    kept = valid - int(s.n_trimmed)
    if int(s.n_outliers) > lim.max_outlier_fraction * max(kept, 1):
        return Verdict(
            "outliers",
            f"effector not static: {int(s.n_outliers)} of {kept} frames lie beyond "
            f"{lim.outlier_mads:g} robust sigmas (limit {lim.max_outlier_fraction:.0%})",
        )
    if used < lim.min_frames:
        return Verdict("too-few-frames", f"only {used} usable frames (need {lim.min_frames})")
    spread = float(s.spread_rms_mm)
    if spread > lim.max_spread_mm:
        return Verdict(
            "spread",
            f"frames scatter {spread:.3f} mm RMS about the centre (limit {lim.max_spread_mm:g} mm): "
            "the effector is vibrating or the markers are badly tracked",
        )
    drift = float(s.drift_total_mm)
    if float(s.drift_p) < lim.drift_alpha and drift > lim.max_drift_mm:
        d = np.asarray(s.drift_mm)
        return Verdict(
            "drift",
            f"effector crept {drift:.3f} mm over {float(s.duration_s):.2f} s "
            f"(dx {d[0]:+.3f}, dy {d[1]:+.3f}, dz {d[2]:+.3f} mm; p = {float(s.drift_p):.1e}; "
            f"limits: p < {lim.drift_alpha:g} and > {lim.max_drift_mm:g} mm)",
        )
    return Verdict(None, "")
