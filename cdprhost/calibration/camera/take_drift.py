"""Did the effector creep during a camera take? Judged on the camera's own noise.

A camera take has a handful of frames, far too few to estimate their noise from
themselves, and that noise is strongly anisotropic (along the camera's line of sight a
frame's B scatters several times more than across it). The session fit knows it: the
frame-to-frame corner noise, pooled over the whole session, carried through each pose's
solution (``SessionFit.frame_noise_covariances``). The drift is the slope of a line
through the frames; with that known covariance ``C`` per frame its covariance is
``C / sum (t - t_mean)^2`` and the Wald statistic ``slope' Cov^-1 slope`` is chi-square
with 3 degrees of freedom when the effector stood still.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class CameraDrift:
    """``drift_mm`` (3,) the fitted displacement over the frames used; ``p`` the chance
    of a drift at least this significant from noise alone (1 when untestable);
    ``duration_s``; ``n_frames`` used."""

    drift_mm: np.ndarray
    p: float
    duration_s: float
    n_frames: int

    @property
    def total_mm(self) -> float:
        return float(np.linalg.norm(self.drift_mm))


def located_frames(points: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frames of a take with a position and a time: ``points`` (F, 3) each frame's B
    (NaN: no position) and ``times`` (F,) s, as (n, 3) and (n,) arrays."""
    x = np.asarray(points, float).reshape(-1, 3)
    t = np.asarray(times, float).ravel()
    ok = np.isfinite(x).all(axis=1) & np.isfinite(t)
    return x[ok], t[ok]


def camera_drift(points: np.ndarray, times: np.ndarray, frame_cov: np.ndarray) -> CameraDrift:
    """The drift test of one take: ``points`` (F, 3) each frame's B (NaN: no position),
    ``times`` (F,) s, ``frame_cov`` (3, 3) the covariance of one frame's B."""
    x, t = located_frames(points, times)
    n = len(t)
    cov = np.asarray(frame_cov, float)
    if n < 3 or not np.isfinite(cov).all():
        return CameraDrift(np.zeros(3), 1.0, float(np.ptp(t)) if n else 0.0, n)
    tc = t - t.mean()
    stt = float(tc @ tc)
    if stt <= 0:
        return CameraDrift(np.zeros(3), 1.0, 0.0, n)
    slope = tc @ (x - x.mean(axis=0)) / stt
    duration = float(np.ptp(t))
    info = np.linalg.pinv(cov) * stt
    wald = float(slope @ info @ slope)
    return CameraDrift(slope * duration, float(stats.chi2.sf(wald, 3)), duration, n)
