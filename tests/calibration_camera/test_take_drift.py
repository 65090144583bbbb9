"""The camera take's drift test on the camera's own (anisotropic) frame noise: sound
takes pass at the test's rate, creeping ones are caught whichever way they creep."""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.camera.take_drift import camera_drift


def _cov(depth_sd: float, lateral_sd: float, seed: int = 0) -> np.ndarray:
    """A frame covariance whose worst axis (the line of sight) points somewhere oblique."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q @ np.diag([lateral_sd**2, lateral_sd**2, depth_sd**2]) @ q.T


def test_sound_takes_pass_at_the_tests_rate_and_depth_noise_is_not_creep():
    cov = _cov(0.25, 0.04)
    chol = np.linalg.cholesky(cov)
    rng = np.random.default_rng(1)
    t = np.arange(4) / 30.0
    p = np.array([camera_drift(rng.normal(size=(4, 3)) @ chol.T, t, cov).p for _ in range(4000)])
    # p is uniform when the effector stands still: 0.1 % of sound takes below 0.001
    assert abs(np.mean(p < 0.05) - 0.05) < 0.012
    assert np.mean(p < 0.001) < 0.004
    # the mocap-style test's error: the frames' own scatter along one axis as the noise
    isotropic = cov.trace() / 3 / 20 * np.eye(3)
    fooled = np.mean(
        [camera_drift(rng.normal(size=(4, 3)) @ chol.T, t, isotropic).p < 0.001 for _ in range(500)]
    )
    assert fooled > 0.05


def test_a_creeping_take_is_caught_across_and_along_the_line_of_sight():
    cov = _cov(0.25, 0.04)
    chol = np.linalg.cholesky(cov)
    w, v = np.linalg.eigh(cov)
    rng = np.random.default_rng(2)
    t = np.arange(4) / 30.0
    ramp = (t - t.mean()) / np.ptp(t)
    across = v[:, 0] * 0.6
    along = v[:, 2] * 2.0
    for creep in (across, along):
        caught = [
            camera_drift(ramp[:, None] * creep + rng.normal(size=(4, 3)) @ chol.T, t, cov)
            for _ in range(200)
        ]
        assert np.mean([c.p < 0.001 for c in caught]) > 0.9
        found = np.median([c.drift_mm @ creep / (creep @ creep) for c in caught])
        assert abs(found - 1.0) < 0.15


def test_too_few_frames_or_no_noise_model_cannot_say_creep():
    assert camera_drift(np.zeros((2, 3)), np.arange(2.0), np.eye(3)).p == 1.0
    assert camera_drift(np.zeros((4, 3)), np.arange(4.0), np.full((3, 3), np.nan)).p == 1.0
