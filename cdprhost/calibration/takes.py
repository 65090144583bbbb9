"""A take judged, whatever measured it: the effector point of every frame in the base
frame (:class:`TakeSeries`, made by a measurement source: :mod:`.mocap.takes` from
motion-capture markers, :mod:`.camera.session` from pictures) -> one measured point with
its standard error (:class:`TakeMeasurement`), or a clear rejection (:class:`TakeRejected`)
with its reason and the numbers behind it. The series is judged by
:mod:`.take_statistics` and :mod:`.acceptance`; the noise's correlation is pooled over the
takes of one session.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.acceptance import AcceptanceLimits, judge
from cdprhost.calibration.take_statistics import TakeStatistics, take_statistics, variance_inflation
from cdprhost.errors import InputError


class TakeRejected(InputError):
    """A take that must not be used; ``reason`` is one of :data:`~.acceptance.REASONS`."""

    def __init__(self, message: str, *, source: str, reason: str):
        super().__init__(message, source=source)
        self.reason = reason


@dataclass(frozen=True, eq=False)
class TakeSeries:
    """A take reduced to what its judgement needs: the effector point of every frame in the
    base frame (NaN where the effector was not seen) and the standard error the source's
    registration into the base frame adds to the point (zero when it has none)."""

    points: np.ndarray  # (frames, 3)
    times_s: np.ndarray  # (frames,)
    registration_se: np.ndarray  # (3,) standard error the registration adds to the point
    base_fit_rms_mm: float
    notes: tuple[str, ...]
    source: str

    @property
    def rate_hz(self) -> float:
        dt = np.diff(self.times_s)
        dt = dt[np.isfinite(dt) & (dt > 0)]
        return float(1.0 / np.median(dt)) if dt.size else 0.0


@dataclass(frozen=True, eq=False)
class TakeMeasurement:
    """The effector point of a sound take (base frame, mm) and how well it is known.

    ``se`` (3,): standard error per coordinate, the frames' (``se_frames``, from the
    long-run variance of the autocorrelated noise), the registration's and, for a take whose
    drift is significant at ``motion_alpha`` but too small to refuse, the motion's
    (drift / sqrt(12) per coordinate) combined;
    ``sigma_mm`` their RMS over coordinates, the pose noise of identification and diagnosis.
    """

    point: np.ndarray
    se: np.ndarray
    se_frames: np.ndarray
    se_registration: np.ndarray
    stats: TakeStatistics
    base_fit_rms_mm: float
    n_frames_total: int
    warnings: tuple[str, ...]
    source: str

    @property
    def sigma_mm(self) -> float:
        return float(np.sqrt(np.mean(self.se**2)))

    @property
    def n_frames_used(self) -> int:
        return int(self.stats.n_used)

    @property
    def spread_mm(self) -> float:
        return float(self.stats.spread_rms_mm)

    @property
    def drift_mm(self) -> float:
        return float(self.stats.drift_total_mm)


# ------------------------------------------------------------------ judgement
def _statistics(
    series: TakeSeries, lim: AcceptanceLimits, noise_inflation: np.ndarray | None = None
) -> TakeStatistics:
    return take_statistics(
        series.points,
        series.times_s,
        outlier_mads=lim.outlier_mads,
        min_scale_mm=lim.min_scale_mm,
        max_settling_fraction=lim.max_settling_fraction,
        settle_alpha=lim.settle_alpha,
        noise_inflation=None if noise_inflation is None else np.asarray(noise_inflation)[None],
    )


def judge_series(
    series: TakeSeries, limits: AcceptanceLimits, stats: TakeStatistics | None = None
) -> TakeMeasurement:
    """The measurement of a registered take, or :class:`TakeRejected` with the reason."""
    s = stats if stats is not None else _statistics(series, limits)
    verdict = judge(s, limits)
    if verdict.reason is not None:
        raise TakeRejected(verdict.message, source=series.source, reason=verdict.reason)
    # an effector that probably moved during the take was at its centre only on average
    moved = float(s.drift_p) < limits.motion_alpha
    se_motion = np.abs(np.asarray(s.drift_mm)) / np.sqrt(12.0) if moved else np.zeros(3)
    se = np.sqrt(s.se**2 + series.registration_se**2 + se_motion**2)
    notes = list(series.notes)
    if moved:
        notes.append(
            f"moved {float(s.drift_total_mm):.3f} mm during the take (p = {float(s.drift_p):.2g}): "
            "counted in its standard error"
        )
    total = int(s.n_frames)
    if int(s.n_valid) < total:
        notes.append(f"{total - int(s.n_valid)} of {total} frames without the effector (gaps)")
    if int(s.n_trimmed):
        notes.append(f"settling: the first {float(s.settled_at_s):.2f} s trimmed")
    if int(s.n_outliers):
        notes.append(f"{int(s.n_outliers)} outlier frame(s) dropped")
    return TakeMeasurement(
        point=np.asarray(s.centre),
        se=se,
        se_frames=np.asarray(s.se),
        se_registration=series.registration_se,
        stats=s,
        base_fit_rms_mm=series.base_fit_rms_mm,
        n_frames_total=total,
        warnings=tuple(notes),
        source=series.source,
    )


def judge_takes(
    series: Sequence[TakeSeries], limits: AcceptanceLimits
) -> list[TakeMeasurement | TakeRejected]:
    """Judge the takes of one session together: the noise's correlation is a property of the
    mocap system, so it is pooled over takes of the same frame rate
    (:func:`~.take_statistics.variance_inflation`) before each take is judged."""
    first = [_statistics(s, limits) for s in series]
    if not first:
        return []
    rates = np.array([round(s.rate_hz, 1) for s in series])
    vif = variance_inflation(
        np.stack([f.autocorrelation for f in first]),
        np.stack([f.pairs for f in first]),
        rates,
    )
    out: list[TakeMeasurement | TakeRejected] = []
    for s, v in zip(series, vif):
        try:
            out.append(judge_series(s, limits, _statistics(s, limits, v)))
        except TakeRejected as exc:
            out.append(exc)
    return out


def judge_in_session(
    series: TakeSeries,
    limits: AcceptanceLimits,
    history: Sequence[tuple[float, TakeStatistics]] = (),
) -> tuple[TakeMeasurement, TakeStatistics]:
    """Judge one new take of a session at once, its noise correlation pooled with the
    ``history`` of (frame rate, first-pass statistics) of the session's sound takes so far.
    Returns the measurement and this take's first-pass statistics (for the history)."""
    first = _statistics(series, limits)
    rate = round(series.rate_hz, 1)
    same = [s for r, s in history if round(r, 1) == rate] + [first]
    vif = variance_inflation(
        np.stack([s.autocorrelation for s in same]),
        np.stack([s.pairs for s in same]),
        np.zeros(len(same), dtype=int),
    )[-1]
    return judge_series(series, limits, _statistics(series, limits, vif)), first
