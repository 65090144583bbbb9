"""A motion-capture take -> one measured effector point in the base frame with its standard
error, or a clear rejection.

The base and the cameras are at rest during a take, so the base frame is registered once:
each base marker's trajectory is reduced to its centre (and standard error) and those
centres are fitted to their base-frame positions (Kabsch). Averaging first removes the
base markers' jitter, which a per-frame fit would carry to the effector through the
lever arm of the base. The effector point of each frame is the centroid of the effector
markers seen in that frame (a marker lost in a gap is stood in for by the others and its
known offset from them), carried into the base frame, plus the configured offset. The
series is then judged like every source's (:mod:`cdprhost.calibration.takes`).

The point's standard error combines the series' own (autocorrelation-aware) standard
error with the registration's: the base-marker centres' standard errors carried to the
effector through the rigid fit (a numerical Jacobian of the Kabsch solution).
A take is refused (:class:`TakeRejected`) with its reason and the numbers behind it.
"""

from __future__ import annotations

import warnings
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.mocap.readers.take import FORMATS, Take
from cdprhost.calibration.mocap.registration import is_degenerate, kabsch
from cdprhost.calibration.take_statistics import take_statistics
from cdprhost.calibration.takes import TakeMeasurement, TakeRejected, TakeSeries, judge_series

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]


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


class MocapConfig(_Strict):
    """``[mocap]`` of session.toml."""

    format: Literal[FORMATS] | None = None  # type: ignore[valid-type]
    base_markers: dict[str, Vec3]
    effector: EffectorConfig
    acceptance: AcceptanceLimits = AcceptanceLimits()
    noise_mm: float | None = Field(
        default=None, gt=0, description="declared mocap noise per coordinate (read by diagnosis)"
    )
    accuracy_mm: float | None = Field(
        default=None,
        gt=0,
        description="the system's accuracy at one place per coordinate, the same in every frame "
        "of a take (calibration-session.md); added to each take's standard error",
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


# ------------------------------------------------------------------ preparation
def _check_markers(take: Take, mocap: MocapConfig) -> None:
    names = list(mocap.base_markers) + list(mocap.effector.markers)
    missing = [n for n in names if n not in take.marker_names]
    if missing:
        shown = ", ".join(take.marker_names[:20]) + (" ..." if len(take.marker_names) > 20 else "")
        raise TakeRejected(
            f"marker(s) {', '.join(missing)} not in the take (it has: {shown})",
            source=take.source,
            reason="missing-marker",
        )
    seen = np.isfinite(take.select(names)).all(axis=2)
    empty = [n for j, n in enumerate(names) if not seen[:, j].any()]
    if empty:
        raise TakeRejected(
            f"marker(s) {', '.join(empty)} never seen (gap in every frame)",
            source=take.source,
            reason="missing-marker",
        )


def effector_centroid(eff: np.ndarray) -> tuple[np.ndarray, int]:
    """Per-frame centroid of the effector markers (frames, m, 3), standing in for a marker lost
    in a gap by its offset from the others (the effector translates only); frames without any
    marker are NaN. Returns the centroids and how many frames were completed that way."""
    seen = np.isfinite(eff).all(axis=2)
    full = seen.all(axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if full.sum() >= 10:
            ref = eff[full]
            offsets = np.mean(ref - ref.mean(axis=1, keepdims=True), axis=0)
        else:
            means = np.nanmean(eff, axis=0)
            offsets = means - means.mean(axis=0)
        centre = np.nanmean(np.where(seen[..., None], eff - offsets[None], np.nan), axis=1)
    partial = int((seen.any(axis=1) & ~full).sum())
    return centre, partial


def registration_se(
    centres: np.ndarray, se: np.ndarray, nominal: np.ndarray, point_mocap: np.ndarray
) -> np.ndarray:
    """Standard error (3,) at ``point_mocap`` of the base-frame point that the rigid fit of
    base-marker ``centres`` (n, 3, mocap frame) with standard errors ``se`` (n, 3) gives."""
    n = centres.shape[0]
    h = 1e-3
    steps = np.eye(3 * n).reshape(3 * n, n, 3) * h
    batch = np.concatenate([centres[None] + steps, centres[None] - steps])
    fits = kabsch(batch, nominal[None])
    moved = fits.apply(np.broadcast_to(point_mocap, (2 * 3 * n, 1, 3)))[:, 0]
    jac = (moved[: 3 * n] - moved[3 * n :]) / (2 * h)  # (3n, 3): d point / d centre coordinate
    return np.asarray(np.sqrt(np.einsum("ki,k->i", jac**2, se.reshape(-1) ** 2)))


def prepare_take(
    take: Take, mocap: MocapConfig, limits: AcceptanceLimits | None = None
) -> TakeSeries:
    """Register a take into the base frame (see module doc); refuses structural problems:
    missing markers, base markers that do not fit session.toml."""
    lim = limits or mocap.acceptance
    src = take.source
    _check_markers(take, mocap)
    names = list(mocap.base_markers)
    nominal = np.asarray([mocap.base_markers[n] for n in names], dtype=float)
    base = take.select(names)  # (frames, n, 3)
    bstats = take_statistics(
        np.moveaxis(base, 1, 0),
        take.times_s,
        groups=np.zeros(len(names), dtype=int),
        outlier_mads=lim.outlier_mads,
        min_scale_mm=lim.min_scale_mm,
    )
    fit = kabsch(bstats.centre, nominal)
    if not bool(fit.valid):
        raise TakeRejected(
            "the base markers' centres are collinear in the take: cannot register",
            source=src,
            reason="base-fit",
        )
    misfit = np.linalg.norm(fit.apply(bstats.centre[None])[0] - nominal, axis=1)
    rms = float(np.sqrt(np.mean(misfit**2)))
    if rms > lim.max_base_rms_mm:
        worst = int(np.argmax(misfit))
        raise TakeRejected(
            f"base-marker fit RMS {rms:.3f} mm exceeds {lim.max_base_rms_mm:g} mm (largest misfit: "
            f"{names[worst]}, {misfit[worst]:.3f} mm): the base marker positions in session.toml do "
            "not match the measured ones, or a base marker moved or is mislabelled",
            source=src,
            reason="base-fit",
        )
    centroid, partial = effector_centroid(take.select(list(mocap.effector.markers)))
    offset = np.asarray(mocap.effector.offset, dtype=float)
    points = fit.apply(centroid[None])[0] + offset
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mid = np.nanmean(centroid, axis=0)
    reg_se = registration_se(bstats.centre, bstats.se, nominal, mid)
    notes = list(take.notes)
    if partial:
        notes.append(f"{partial} frame(s) completed from the effector markers seen")
    moved = [
        n
        for n, p, d in zip(names, bstats.drift_p, bstats.drift_total_mm)
        if p < lim.drift_alpha and d > lim.max_drift_mm
    ]
    if moved:
        notes.append(f"base marker(s) {', '.join(moved)} moved during the take")
    return TakeSeries(points, take.times_s, reg_se, rms, tuple(notes), src)


def measure_effector(
    take: Take, mocap: MocapConfig, limits: AcceptanceLimits | None = None
) -> TakeMeasurement:
    """Measure one take on its own (its noise correlation estimated from itself)."""
    lim = limits or mocap.acceptance
    return judge_series(prepare_take(take, mocap, lim), lim)
