"""One honest noise model (issue 11, deliver 2): on realistic virtual motion capture the pose
noise from the takes' standard errors gives the right noise floor and chi-square."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.session import load_session
from cdprhost.diagnosis import crossval, signatures
from cdprhost.diagnosis.workflow import FAST, diagnose
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times
from cdprhost.sim.synthetic_session import write_measured_session
from tests.diagnosis.sessions import SESSION_MOCAP


@pytest.mark.parametrize("jitter_mm", [0.05, 0.15, 0.25])
def test_noise_floor_and_chi2_of_a_correct_model(tmp_path, sim_model, jitter_mm):
    rng = np.random.default_rng(int(jitter_mm * 1000))
    truth = hidden_truth(sim_model, rng, None)
    poses = measurement_tour(sim_model, 40, rng)
    written = write_measured_session(
        tmp_path / "s",
        truth,
        sim_model,
        poses,
        session_times(40, rng),
        realism=SESSION_MOCAP.__class__(**{**vars(SESSION_MOCAP), "jitter_mm": jitter_mm}),
        rate_hz=120.0,
        duration_s=2.0,
        seed=int(jitter_mm * 1000) + 1,
    )
    meas = load_session(tmp_path / "s").measure()
    assert len(meas) == 40, [str(r) for r in meas.rejected]
    noise = meas.noise(sim_model.steps_per_mm)
    obs = meas.observations(noise)
    d = diagnose(obs, sim_model, noise, FAST)
    assert d.verdict == "none"
    # the truth: the realised errors of the measured points
    err = meas.measured - written.actual
    true_sigma = float(np.sqrt(np.mean(err**2)))
    folds = crossval.pose_folds(len(obs), FAST.folds)
    jac = signatures.fit_jacobian(d.base.fit, obs)
    true_floor = crossval.noise_floor_mm(jac, true_sigma, folds)
    assert 0.75 < d.noise_floor_mm / true_floor < 1.25, (d.noise_floor_mm, true_floor)
    assert 0.7 < d.base.chi2 / d.base.dof < 1.4, (d.base.chi2, d.base.dof)
    assert noise.source == "takes" and noise.extra_mm == 0.0
