"""Did the effector stand still between a camera take's frames? Judged on the camera's
own noise.

The motion-capture cap on a take's spread (``max_spread_mm``, 1 mm RMS) is a figure for
markers tracked to a few hundredths of a millimetre; a camera frame's B scatters by
tenths of a millimetre across the line of sight and several times more along it (at 720p
and 1.1 m over a millimetre), so that cap refuses sound camera takes and would not notice
a shaking effector seen from close. What the camera predicts is known: the covariance
``C`` of one frame's B (``SessionFit.frame_noise_covariances``, the session's pooled
frame-to-frame corner noise through the pose's solution).

The frames' scatter is measured about the straight line through them (a slow creep is the
drift test's, :mod:`.take_drift`, with its own physical threshold): with ``n`` frames the
residuals' ``sum r' C^-1 r`` is chi-square with ``3 (n - 2)`` degrees of freedom when the
effector stood still, and a take is refused when it is improbably large (a shaking
effector, a board that slipped between frames). Together with the drift test's Wald
statistic it is the frames' whole scatter about their mean in the covariance's metric.

The model's ellipsoid is thin (at 720p and 1.1 m ten times longer than wide) and its
orientation is known only to a few degrees, so a slightly misaligned one would call part
of the depth noise lateral scatter: every direction gets at least a tenth of the longest
axis's standard deviation (:data:`ANISOTROPY_FLOOR`) before the test. On rendered
sessions that leaves no sound take below p = 0.001 (two in 91 were, without it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from cdprhost.calibration.camera.take_drift import located_frames

#: The least standard deviation in any direction, as a fraction of the longest axis's.
ANISOTROPY_FLOOR = 0.1


@dataclass(frozen=True)
class CameraScatter:
    """``rms_mm`` the frames' RMS distance from their line; ``expected_rms_mm`` what the
    camera's frame noise predicts for it; ``p`` the chance of a scatter at least this large
    (in the covariance's metric) from noise alone (1 when untestable); ``n_frames`` used;
    ``chi2`` the statistic on ``dof`` degrees of freedom (0: untestable)."""

    rms_mm: float
    expected_rms_mm: float
    p: float
    n_frames: int
    chi2: float = 0.0
    dof: int = 0

    @property
    def ratio(self) -> float:
        """The scatter in units of the predicted one (1 for a typical sound take)."""
        return self.rms_mm / self.expected_rms_mm if self.expected_rms_mm > 0 else float("nan")


def camera_scatter(points: np.ndarray, times: np.ndarray, frame_cov: np.ndarray) -> CameraScatter:
    """The scatter test of one take: ``points`` (F, 3) each frame's B (NaN: no position),
    ``times`` (F,) s, ``frame_cov`` (3, 3) the covariance of one frame's B."""
    x, t = located_frames(points, times)
    n = len(t)
    cov = np.asarray(frame_cov, float)
    tc = t - t.mean() if n else t
    stt = float(tc @ tc)
    if n < 3 or stt <= 0 or not np.isfinite(cov).all():
        return CameraScatter(float("nan"), float("nan"), 1.0, n)
    floored = cov + ANISOTROPY_FLOOR**2 * float(np.linalg.eigvalsh(cov).max()) * np.eye(3)
    xc = x - x.mean(axis=0)
    resid = xc - np.outer(tc, tc @ xc / stt)
    dof = 3 * (n - 2)
    chi2 = float(np.einsum("fi,ij,fj->", resid, np.linalg.pinv(floored), resid))
    return CameraScatter(
        float(np.sqrt(np.sum(resid**2) / n)),
        float(np.sqrt(np.trace(cov) * (n - 2) / n)),
        float(stats.chi2.sf(chi2, dof)),
        n,
        chi2,
        dof,
    )
