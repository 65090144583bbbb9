"""A session's measurements, whatever measured them: the accepted poses' effector points
with their noise (:class:`SessionMeasurements`), the refused takes listed apart
(:class:`RejectedTake`), and the one builder of the observations that identification,
the trust gate and diagnosis take. The motion-capture source fills them in
:meth:`~cdprhost.calibration.session.Session.measure`, the camera source in
:func:`~cdprhost.calibration.camera.session.measure_camera_session`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.pose_noise import PoseNoise, camera_noise, pose_noise
from cdprhost.calibration.takes import TakeMeasurement


@dataclass(frozen=True, eq=False)
class RejectedTake:
    pose: int
    take: str
    reason: str  # one of acceptance.REASONS
    message: str

    def __str__(self) -> str:
        return f"pose {self.pose} ({self.take}): {self.reason}: {self.message}"


@dataclass(frozen=True, eq=False)
class SessionMeasurements:
    """Accepted poses only (K of them), in poses.csv order; refused ones listed apart."""

    pose: np.ndarray  # (K,)
    roles: tuple[str, ...]
    measured: np.ndarray  # (K, 3) base frame, mm
    commanded: np.ndarray  # (K, 3)
    s_cmd: np.ndarray  # (K, 3)
    t_s: np.ndarray  # (K,)
    dirs: np.ndarray  # (K, 3)
    se: np.ndarray  # (K, 3) standard error of each take's centre
    base_fit_rms_mm: np.ndarray  # (K,)
    takes: tuple[TakeMeasurement, ...]
    rejected: tuple[RejectedTake, ...]
    declared_noise_mm: float | None = None
    # a camera session's noise (camera-session.md, :mod:`.camera.session`): each pose's full
    # covariance (K, 3, 3), the common vector's (3, 3), the parameters' part (12, 12); what
    # refuses the session whatever the fit (calibration views of poor coverage); notes
    covariance: np.ndarray | None = None
    common_covariance: np.ndarray | None = None
    parameter_covariance: np.ndarray | None = None
    frame_covariance: np.ndarray | None = None
    refusals: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.measured.shape[0])

    @property
    def take_sigma_mm(self) -> np.ndarray:
        """Each pose's noise from its take alone, (K,) mm per coordinate."""
        return np.sqrt(np.mean(self.se**2, axis=1)) if len(self) else np.zeros(0)

    def noise(
        self, steps_per_mm: np.ndarray | float = 400.0, *, floor_mm: float | None = None
    ) -> PoseNoise:
        """The one noise model (:func:`~.pose_noise.pose_noise`); ``floor_mm`` overrides the
        declared noise."""
        if self.covariance is not None:
            return camera_noise(
                self.covariance,
                self.take_sigma_mm,
                self.declared_noise_mm if floor_mm is None else floor_mm,
                self.common_covariance,
                self.parameter_covariance,
                self.frame_covariance,
            )
        return pose_noise(
            self.take_sigma_mm,
            declared_mm=self.declared_noise_mm if floor_mm is None else floor_mm,
            sliders=self.s_cmd,
            measured=self.measured,
            steps_per_mm=steps_per_mm,
        )

    def observations(self, noise: PoseNoise | None = None) -> Observations:
        """The observations of identification and diagnosis (the one builder)."""
        n = noise or self.noise()
        return Observations(
            self.measured, self.s_cmd, self.t_s, self.dirs.astype(float), n.sigma_mm, n.covariance
        )
