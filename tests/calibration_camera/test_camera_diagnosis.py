"""Diagnosis on camera positions with the camera's noise model: a hidden drive_scale is
named with its values and the gap shrinks; clean data give ``none``."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.camera import fit_session
from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.pose_noise import camera_noise
from cdprhost.diagnosis.workflow import FAST, diagnose
from cdprhost.sim.scenarios import hidden_truth, measurement_tour
from tests.calibration_camera.scene import analytic_takes, make_scene
from tests.calibration_camera.test_session_fit import calibrated


def camera_diagnosis(model, effect, seed, n_poses=30):
    rng = np.random.default_rng(seed)
    truth = hidden_truth(model, rng, effect)
    scene = make_scene()
    poses = measurement_tour(model, n_poses, rng)
    s_cmd, dirs = commanded_path(model, poses)
    takes = analytic_takes(scene, truth.fk(s_cmd), 4, rng)
    fit = fit_session(takes, scene.setup, calibrated(scene.intrinsics))
    noise = camera_noise(fit.covariances, np.zeros(n_poses), None, fit.common_covariance)
    obs = Observations(
        fit.positions, s_cmd, None, dirs.astype(float), noise.sigma_mm, noise.covariance
    )
    return truth, diagnose(obs, model, noise, FAST)


@pytest.mark.slow
def test_hidden_drive_scale_is_named_from_camera_positions(sim_model):
    truth, d = camera_diagnosis(sim_model, "drive_scale", 3)
    assert d.verdict == "named" and d.effects == ("drive_scale",), (d.verdict, d.where)
    vec = np.asarray(d.parameters["drive_scale"]["vector"])
    se = np.asarray(d.parameters["drive_scale"]["stderr"])
    true_vec = truth.effects.vectors[0]
    assert np.all(np.abs(vec - true_vec) <= 3 * se), (vec, true_vec, se)
    assert d.base.heldout_rms_mm > 3 * d.final.heldout_rms_mm
    assert d.final.heldout_rms_mm <= 1.3 * d.noise_floor_mm


@pytest.mark.slow
def test_clean_camera_session_gives_none(sim_model):
    _, d = camera_diagnosis(sim_model, None, 2)
    assert d.verdict == "none", (d.verdict, d.effects, d.where)
