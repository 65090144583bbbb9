"""Identification: the paper's section 5.2 case, noisy planned sessions, check poses, failures."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.fitting import CableModelFit, Observations
from cdprhost.calibration.identification import calibrated_profile, identify
from cdprhost.calibration.planning import TABLE1_POSES
from cdprhost.profile import load_profile, save_profile
from cdprhost.sim.measurement import perturbed_geometry, simulate_observations


def test_paper_section_5_2_converges_to_truth(sim_model, paper_truth):
    obs = simulate_observations(paper_truth, sim_model, TABLE1_POSES, noise_mm=0.0)
    before = np.linalg.norm(sim_model.fk(obs.sliders) - obs.measured, axis=1)
    assert 13.0 < before.max() < 15.0  # paper: 14.42 mm
    est = CableModelFit().fit(Observations(obs.measured, obs.sliders, sigma_mm=0.05), sim_model)
    assert est.converged_
    assert est.updates_until(1e-4) <= 6  # paper: 4 iterations to the 1e-4 mm threshold
    assert est.iterations_ <= 6
    np.testing.assert_allclose(est.x_, paper_truth.geometry.q, atol=1e-6)
    after = np.linalg.norm(est.model_.fk(obs.sliders) - obs.measured, axis=1)
    assert after.max() < 1e-6
    result = identify(obs, sim_model)
    assert result.converged and result.iterations <= 6 and result.rms_after_mm < 1e-6


def test_iterates_record_each_parameter_update(sim_model, paper_truth):
    obs = simulate_observations(paper_truth, sim_model, TABLE1_POSES, noise_mm=0.0)
    est = CableModelFit().fit(Observations(obs.measured, obs.sliders), sim_model)
    np.testing.assert_array_equal(est.iterates_[0], sim_model.geometry.q)
    np.testing.assert_array_equal(est.iterates_[-1], est.x_)
    steps = np.abs(np.diff(est.iterates_, axis=0)).max(axis=1)
    assert steps[0] > 1.0 and steps[-1] < 1e-6  # quadratic convergence from mm to nothing


@pytest.fixture(scope="module")
def noisy_truth(sim_model):
    return sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(11))
    )


def test_planned_session_recovers_truth_within_stated_uncertainty(sim_model, noisy_truth, plan12):
    obs = simulate_observations(
        noisy_truth, sim_model, plan12.poses, noise_mm=0.05, rng=np.random.default_rng(12)
    )
    r = identify(obs, sim_model)
    assert r.ok and r.poses_used == 12 and r.dof == 24
    assert r.rms_before_mm > 1.0 and r.rms_after_mm < 0.1
    z = (r.geometry.q - noisy_truth.geometry.q) / r.stderr
    assert np.all(np.abs(z) < 4.5)
    inside = (r.ci95[:, 0] <= noisy_truth.geometry.q) & (noisy_truth.geometry.q <= r.ci95[:, 1])
    assert inside.sum() >= 9
    assert r.chi2 / r.dof < 3.0
    assert r.singular_values.shape == (12,) and not r.unidentifiable


def test_check_poses_are_predicted_not_fitted(sim_model, noisy_truth, plan4):
    obs = simulate_observations(
        noisy_truth, sim_model, plan4.poses, noise_mm=0.05, rng=np.random.default_rng(13)
    )
    r = identify(obs, sim_model, plan4.roles)
    assert r.poses_used == 4 and r.dof == 0
    assert r.rms_after_mm < 1e-6  # 4 poses fit exactly (no redundancy)...
    assert (
        0.0 < r.check_rms_after_mm < 1.0 < r.check_rms_before_mm
    )  # ...the check poses tell the truth
    only_fit = identify(obs.subset(np.flatnonzero(np.array(plan4.roles) == "fit")), sim_model)
    np.testing.assert_allclose(only_fit.geometry.q, r.geometry.q, atol=1e-8)


def test_too_few_poses_is_not_ok(sim_model, noisy_truth, plan4):
    obs = simulate_observations(noisy_truth, sim_model, plan4.fit_poses[:3], noise_mm=0.05)
    r = identify(obs, sim_model)
    assert not r.ok and "at least 4" in r.problems()[0]


def test_degenerate_poses_are_named_unidentifiable(sim_model, noisy_truth):
    poses = np.repeat(np.array([[0.0, 0.0, 200.0], [30.0, 10.0, 250.0]]), 3, axis=0)
    obs = simulate_observations(noisy_truth, sim_model, poses, noise_mm=0.0)
    r = identify(obs, sim_model)
    assert not r.ok
    assert r.unidentifiable and all("*" in combo for combo in r.unidentifiable)


def test_calibrated_profile_round_trips_with_provenance(
    sim_profile, sim_model, noisy_truth, plan12, tmp_path
):
    obs = simulate_observations(
        noisy_truth, sim_model, plan12.poses, noise_mm=0.05, rng=np.random.default_rng(14)
    )
    r = identify(obs, sim_model)
    prof = calibrated_profile(sim_profile, r, session="/data/session-1")
    save_profile(prof, tmp_path / "cal.toml")
    back = load_profile(tmp_path / "cal.toml")
    np.testing.assert_allclose(np.array(back.geometry.outlets), r.geometry.outlets)
    np.testing.assert_allclose(np.array(back.geometry.initial_lengths), r.geometry.initial_lengths)
    assert back.calibration["session"] == "/data/session-1"
    assert back.calibration["rms_after_mm"] == pytest.approx(r.rms_after_mm)
    assert np.array(back.calibration["stderr_outlets_mm"]).shape == (3, 3)
    assert back.statics == sim_profile.statics and back.drive == sim_profile.drive


def test_report_json_has_contract_fields(sim_model, noisy_truth, plan12):
    obs = simulate_observations(
        noisy_truth, sim_model, plan12.poses, noise_mm=0.05, rng=np.random.default_rng(15)
    )
    data = identify(obs, sim_model).to_json()
    assert np.array(data["parameters"]["outlets"]).shape == (3, 3)
    assert len(data["parameters"]["initial_lengths"]) == 3
    assert (
        np.array(data["stderr"]["outlets"]).shape == (3, 3)
        and len(data["stderr"]["initial_lengths"]) == 3
    )
    for key in ("rms_before_mm", "rms_after_mm", "iterations", "poses_used"):
        assert key in data
    assert data["poses_used"] == 12 and len(data["poses"]) == 12
