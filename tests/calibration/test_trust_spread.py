"""The trust gate's spread (issue 31): one calibration's workspace RMS is one draw of an
error with few effective directions; the gate states the range it falls in, and that
range holds for draws of the same covariance."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.identification import identify
from cdprhost.calibration.planning import plan_poses
from cdprhost.calibration.report import trust_text
from cdprhost.calibration.trust import (
    error_spectrum,
    frame_metric,
    rms_quantile,
    trust_report,
)
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.kinematics.jacobian import identification_jacobian
from cdprhost.sim.measurement import perturbed_geometry, simulate_observations


@pytest.fixture(scope="module")
def fitted(sim_model):
    truth = sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(31), 2.0)
    )
    obs = simulate_observations(
        truth,
        sim_model,
        plan_poses(sim_model, 8).poses,
        noise_mm=0.05,
        rng=np.random.default_rng(7),
    )
    return identify(obs, sim_model)


def one_direction(r, grid):
    """A camera-like shared error: one parameter direction (a frame moved along a line of
    sight) carrying most of the workspace error."""
    j0 = identification_jacobian(grid, r.geometry).reshape(-1, 3, 12)
    mean = np.einsum("nip->ip", j0) / j0.shape[0]
    v = np.linalg.lstsq(mean, np.array([0.0, 0.77, -0.64]), rcond=None)[0]
    return 0.15**2 * np.outer(v, v)


def draws(r, cov, common, frame, grid, n=4000):
    """The workspace RMS of n calibrations drawn from the stated covariances."""
    rng = np.random.default_rng(5)
    j0 = identification_jacobian(grid, r.geometry).reshape(-1, 3, 12)
    dq = rng.multivariate_normal(np.zeros(12), cov, n)
    c = rng.multivariate_normal(np.zeros(3), common, n)
    wt = rng.multivariate_normal(np.zeros(6), frame, n)
    x = grid
    rigid = np.cross(wt[:, None, :3], x[None]) + wt[:, None, 3:]
    err = np.einsum("nip,sp->sni", j0, dq) + c[:, None] + rigid
    return np.sqrt(np.mean(np.sum(err**2, axis=2), axis=1))


def test_one_dominant_direction_gives_few_degrees_of_freedom_and_a_wide_range(fitted, sim_model):
    grid = workspace_grid(sim_model)
    extra = one_direction(fitted, grid)
    common = np.diag([0.01, 0.02, 0.005]) ** 2
    frame = np.diag([1e-5, 2e-5, 1e-5, 0.01, 0.01, 0.02]) ** 2
    t = trust_report(
        fitted.geometry,
        fitted.covariance,
        np.linalg.pinv(fitted.covariance),
        grid,
        1.0,
        10,
        parameter_covariance=extra,
        common_covariance=common,
        frame_covariance=frame,
    )
    spectrum = error_spectrum(fitted.geometry, fitted.covariance + extra, grid, common, frame)
    # the spectrum adds up to the predicted mean square
    assert spectrum.sum() == pytest.approx(t.predicted_rms_mm**2, rel=1e-6)
    assert t.effective_dof < 2.0
    lo, hi = t.likely_rms_mm
    assert lo < t.predicted_rms_mm / 1.5  # a single draw may well fall outside 1.5x
    rms = draws(fitted, fitted.covariance + extra, common, frame, grid)
    assert np.mean(rms**2) == pytest.approx(t.predicted_rms_mm**2, rel=0.08)
    assert np.quantile(rms, 0.1) == pytest.approx(lo, rel=0.2)
    assert np.quantile(rms, 0.9) == pytest.approx(hi, rel=0.1)
    assert np.mean((rms > lo) & (rms < hi)) == pytest.approx(0.8, abs=0.05)
    # observed RMS values of those draws are spread evenly over the predicted distribution
    q = np.array([rms_quantile(spectrum, v) for v in rms[:400]])
    assert np.histogram(q, bins=4, range=(0, 1))[0].min() > 60


def test_many_directions_give_a_narrow_range(fitted, sim_model):
    grid = workspace_grid(sim_model)
    t = trust_report(
        fitted.geometry,
        fitted.covariance,
        np.linalg.pinv(fitted.covariance),
        grid,
        1.0,
        10,
        common_covariance=0.05**2 * np.eye(3),
        frame_covariance=np.diag([1e-5] * 3 + [0.05] * 3) ** 2,
    )
    lo, hi = t.likely_rms_mm
    assert t.effective_dof > 4.0
    assert t.predicted_rms_mm / 1.5 < lo < t.predicted_rms_mm < hi < 1.5 * t.predicted_rms_mm


def test_the_report_states_the_spread(fitted):
    text = trust_text(fitted)
    assert "8 times out of 10" in text
    assert "effective degrees of freedom" in text
    assert fitted.trust is not None
    assert fitted.to_json()["trust"]["likely_workspace_rms_mm"] == list(fitted.trust.likely_rms_mm)


def test_frame_metric_is_the_mean_square_of_a_rigid_error(sim_model):
    grid = workspace_grid(sim_model)
    w = np.array([1e-4, -2e-4, 3e-4, 0.1, 0.0, -0.2])
    moved = np.cross(w[:3], grid) + w[3:]
    assert w @ frame_metric(grid) @ w == pytest.approx(np.mean(np.sum(moved**2, axis=1)))
