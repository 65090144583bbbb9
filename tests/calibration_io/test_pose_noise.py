"""The one pose-noise model: take standard errors, plus a declared or replicate part."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.pose_noise import pose_noise, repeated_pose_scatter


def test_take_standard_errors_are_the_noise_by_default():
    take = np.array([0.01, 0.02, 0.03])
    n = pose_noise(take, sliders=np.arange(9.0).reshape(3, 3), measured=np.zeros((3, 3)))
    np.testing.assert_allclose(n.sigma_mm, take)
    assert n.source == "takes" and n.extra_mm == 0.0
    assert n.typical_mm == pytest.approx(np.sqrt(np.mean(take**2)))


def test_declared_noise_adds_in_quadrature():
    n = pose_noise(np.array([0.03, 0.04]), declared_mm=0.04)
    np.testing.assert_allclose(n.sigma_mm, [0.05, np.sqrt(0.0032)])
    assert n.source == "takes + declared" and "0.04" in n.note


def test_repeated_poses_reveal_what_takes_cannot_see():
    rng = np.random.default_rng(5)
    sliders = np.repeat(rng.uniform(-100, 0, (10, 3)), 4, axis=0)
    measured = np.repeat(rng.uniform(-50, 50, (10, 3)), 4, axis=0) + rng.normal(0, 0.08, (40, 3))
    sigma, dof, mask = repeated_pose_scatter(sliders, measured)
    assert dof == 90 and sigma == pytest.approx(0.08, rel=0.2) and mask.all()
    n = pose_noise(np.full(40, 0.02), sliders=sliders, measured=measured)
    assert n.source == "takes + repeated poses"
    assert n.extra_mm == pytest.approx(np.sqrt(sigma**2 - 0.02**2))
    # replicates that scatter no more than the takes say add nothing
    quiet = np.repeat(rng.uniform(-50, 50, (10, 3)), 4, axis=0) + rng.normal(0, 0.01, (40, 3))
    assert pose_noise(np.full(40, 0.02), sliders=sliders, measured=quiet).extra_mm == 0.0


def test_too_few_replicates_are_not_believed():
    sliders = np.array([[0, 0, 0], [0, 0, 0], [1, 1, 1.0]])
    assert repeated_pose_scatter(sliders, np.zeros((3, 3))) is None
