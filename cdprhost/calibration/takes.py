"""One take -> one measured effector point in the base frame, or a clear rejection.

Per frame: fit the base markers to their base-frame positions (Kabsch), carry the
effector markers' centroid into the base frame, add the offset. Over frames:
drop outliers (median/MAD), average the rest. A take is rejected (``TakeRejected``)
when a marker is missing, the base fit is implausible, the effector moved, or too
few frames remain; the numbers behind each verdict are in the message.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from cdprhost.calibration.readers.take import FORMATS, Take
from cdprhost.calibration.registration import is_degenerate, register_frames
from cdprhost.errors import InputError

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
MAD_TO_SIGMA = 1.4826


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class EffectorConfig(_Strict):
    """The effector point B = centroid of ``markers`` + ``offset`` (base frame, mm)."""

    markers: tuple[str, ...] = Field(min_length=1)
    offset: Vec3 = (0.0, 0.0, 0.0)

    @field_validator("markers")
    @classmethod
    def _unique(cls, markers: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(markers)) != len(markers):
            raise ValueError("effector markers must be distinct")
        return markers


class AcceptanceLimits(_Strict):
    """When a take is believed. Defaults suit a static effector and a surveyed base."""

    max_base_rms_mm: float = Field(0.5, gt=0)
    max_spread_mm: float = Field(0.5, gt=0)
    min_frames: int = Field(10, ge=1)
    outlier_mads: float = Field(5.0, gt=0)
    max_outlier_fraction: float = Field(0.25, ge=0, lt=1)
    min_scale_mm: float = Field(
        0.005, gt=0, description="floor of the robust scale (quantised exports)"
    )


class MocapConfig(_Strict):
    """``[mocap]`` of session.toml."""

    format: Literal[FORMATS] | None = None  # type: ignore[valid-type]
    base_markers: dict[str, Vec3]
    effector: EffectorConfig
    acceptance: AcceptanceLimits = AcceptanceLimits()
    noise_mm: float | None = Field(
        None, gt=0, description="declared mocap noise per coordinate (read by diagnosis)"
    )

    @field_validator("base_markers")
    @classmethod
    def _base_ok(cls, markers: dict[str, Vec3]) -> dict[str, Vec3]:
        if len(markers) < 3:
            raise ValueError(f"need at least 3 base markers, got {len(markers)}")
        if is_degenerate(np.array(list(markers.values()))):
            raise ValueError(
                "base markers are collinear (or coincide): the base frame would be ambiguous"
            )
        return markers

    @model_validator(mode="after")
    def _disjoint(self) -> MocapConfig:
        both = sorted(set(self.base_markers) & set(self.effector.markers))
        if both:
            raise ValueError(
                f"marker(s) {', '.join(both)} listed both on the base and on the effector"
            )
        return self


class TakeRejected(InputError):
    """A take that must not be used. ``reason``: missing-marker | base-fit | not-static | too-few-frames."""

    def __init__(self, message: str, *, source: str, reason: str):
        super().__init__(message, source=source)
        self.reason = reason


@dataclass(frozen=True, eq=False)
class TakeMeasurement:
    """The averaged effector point (base frame, mm) and how good it is.

    ``std``: per-coordinate standard deviation over the frames used; ``sem`` =
    std / sqrt(n) is the frame-noise part of the point's uncertainty.
    ``spread_mm``: largest distance of a used frame from the point.
    """

    point: np.ndarray
    std: np.ndarray
    n_frames_used: int
    n_frames_total: int
    base_fit_rms_mm: float
    spread_mm: float
    warnings: tuple[str, ...]
    source: str

    @property
    def sem(self) -> np.ndarray:
        return self.std / np.sqrt(max(self.n_frames_used, 1))


def robust_inliers(points: np.ndarray, n_mads: float, min_scale: float) -> np.ndarray:
    """Mask of rows within ``n_mads`` robust sigmas (MAD * 1.4826) of the median in every coordinate."""
    med = np.median(points, axis=0)
    dev = np.abs(points - med)
    scale = np.maximum(MAD_TO_SIGMA * np.median(dev, axis=0), min_scale)
    return np.all(dev <= n_mads * scale, axis=1)


def measure_effector(
    take: Take, mocap: MocapConfig, limits: AcceptanceLimits | None = None
) -> TakeMeasurement:
    """Average the effector point of a static take in the base frame (see module doc)."""
    lim = limits or mocap.acceptance
    src = take.source
    base = list(mocap.base_markers)
    eff = list(mocap.effector.markers)
    missing = [n for n in base + eff if n not in take.marker_names]
    if missing:
        shown = ", ".join(take.marker_names[:20]) + (" ..." if len(take.marker_names) > 20 else "")
        raise TakeRejected(
            f"marker(s) {', '.join(missing)} not in the take (it has: {shown})",
            source=src,
            reason="missing-marker",
        )
    seen = np.isfinite(take.positions).all(axis=2)  # (frames, markers)
    empty = [n for n in base + eff if not seen[:, take.index(n)].any()]
    if empty:
        raise TakeRejected(
            f"marker(s) {', '.join(empty)} never seen (gap in every frame)",
            source=src,
            reason="missing-marker",
        )

    reg = register_frames(take, mocap.base_markers)
    eff_pos = take.select(eff)
    eff_ok = np.isfinite(eff_pos).all(axis=(1, 2))
    usable = reg.valid & eff_ok
    n_usable = int(usable.sum())
    if n_usable < lim.min_frames:
        raise TakeRejected(
            f"only {n_usable} of {take.n_frames} frames have every effector marker and 3 base markers "
            f"(need {lim.min_frames})",
            source=src,
            reason="too-few-frames",
        )
    centroid = np.where(eff_ok[:, None, None], eff_pos, 0.0).mean(axis=1)
    points = reg.apply(centroid[:, None, :])[:, 0] + np.asarray(mocap.effector.offset)
    rms = reg.rms_residual
    base_rms = float(np.median(rms[usable]))
    if base_rms > lim.max_base_rms_mm:
        worst, worst_mm = _worst_base_marker(take, mocap, reg, usable)
        raise TakeRejected(
            f"base-marker fit RMS {base_rms:.3f} mm exceeds {lim.max_base_rms_mm} mm (largest misfit: {worst}, "
            f"{worst_mm:.3f} mm): the base marker positions in session.toml do not match the measured ones, "
            "or a base marker moved or is mislabelled",
            source=src,
            reason="base-fit",
        )

    idx = np.flatnonzero(usable)
    inl = robust_inliers(points[idx], lim.outlier_mads, lim.min_scale_mm)
    inl &= rms[idx] <= lim.max_base_rms_mm
    n_out = int((~inl).sum())
    if n_out > lim.max_outlier_fraction * len(idx):
        raise TakeRejected(
            f"effector not static: {n_out} of {len(idx)} frames lie beyond {lim.outlier_mads} robust sigmas "
            f"or have a base fit over {lim.max_base_rms_mm} mm (limit {lim.max_outlier_fraction:.0%} of frames)",
            source=src,
            reason="not-static",
        )
    used = points[idx[inl]]
    if len(used) < lim.min_frames:
        raise TakeRejected(
            f"only {len(used)} frames left after outlier rejection (need {lim.min_frames})",
            source=src,
            reason="too-few-frames",
        )
    point = used.mean(axis=0)
    spread = float(np.max(np.linalg.norm(used - point, axis=1)))
    if spread > lim.max_spread_mm:
        raise TakeRejected(
            f"effector not static: frames spread {spread:.3f} mm from the average (limit {lim.max_spread_mm} mm)",
            source=src,
            reason="not-static",
        )
    std = used.std(axis=0, ddof=1) if len(used) > 1 else np.zeros(3)
    warnings = list(take.notes)
    if n_usable < take.n_frames:
        warnings.append(f"{take.n_frames - n_usable} of {take.n_frames} frames skipped for gaps")
    if n_out:
        warnings.append(f"{n_out} outlier frame(s) dropped")
    partial = int((usable & (reg.n_points < len(base))).sum())
    if partial:
        warnings.append(f"{partial} frame(s) registered without every base marker")
    return TakeMeasurement(
        point, std, len(used), take.n_frames, base_rms, spread, tuple(warnings), src
    )


def _worst_base_marker(
    take: Take, mocap: MocapConfig, reg, usable: np.ndarray
) -> tuple[str, float]:
    names = list(mocap.base_markers)
    nominal = np.asarray([mocap.base_markers[n] for n in names])
    fitted = reg.apply(take.select(names))[usable]
    err = np.nanmedian(np.linalg.norm(fitted - nominal, axis=2), axis=0)
    k = int(np.nanargmax(err))
    return names[k], float(err[k])
