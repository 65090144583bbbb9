import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.calibration.fitting import CableModelFit
from cdprhost.diagnosis.crossval import (
    expected_heldout_sq,
    heldout_errors,
    noise_floor_mm,
    pose_folds,
    rms,
)
from cdprhost.diagnosis.signatures import fit_jacobian


@given(st.integers(2, 80), st.integers(2, 12))
def test_pose_folds_partition_the_poses(n, k):
    folds = pose_folds(n, k)
    joined = np.sort(np.concatenate(folds))
    np.testing.assert_array_equal(joined, np.arange(n))
    assert len(folds) == min(k, n)
    sizes = [len(f) for f in folds]
    assert max(sizes) - min(sizes) <= 1


def test_expected_heldout_for_a_linear_model_matches_monte_carlo():
    rng = np.random.default_rng(3)
    n, p, sigma = 30, 4, 0.05
    x = rng.normal(size=(3 * n, p))  # whitened design, 3 rows per pose
    folds = pose_folds(n, 5)
    expected = expected_heldout_sq(x, sigma, folds)
    sq = np.zeros(n)
    trials = 400
    for _ in range(trials):
        y = rng.normal(0, sigma, 3 * n)
        for test in folds:
            train = np.setdiff1d(np.arange(n), test)
            rows = (3 * train[:, None] + np.arange(3)).ravel()
            beta = np.linalg.lstsq(x[rows], y[rows], rcond=None)[0]
            trow = (3 * test[:, None] + np.arange(3)).ravel()
            err = (y[trow] - x[trow] @ beta).reshape(-1, 3)
            sq[test] += np.sum(err * err, axis=1)
    np.testing.assert_allclose(sq / trials, expected, rtol=0.15)
    assert np.sqrt(np.mean(sq / trials)) == pytest.approx(np.sqrt(np.mean(expected)), rel=0.03)


def test_noise_floor_matches_heldout_rms_of_a_correct_model(make_session, sim_model):
    ratios = []
    for seed in range(12):
        _, _, obs = make_session(None, 100 + seed)
        fit = CableModelFit().fit(obs, sim_model)
        folds = pose_folds(len(obs), 5)
        held = rms(heldout_errors(obs, fit.model_, (), folds))
        ratios.append(held / noise_floor_mm(fit_jacobian(fit, obs), obs.sigma_mm, folds))
    assert 0.93 < np.mean(ratios) < 1.07  # a correct model sits on its noise floor
    assert (
        1.6 < noise_floor_mm(fit_jacobian(fit, obs), 0.05, folds) / 0.05 < 2.0
    )  # ~ sqrt(3 + leverage)
