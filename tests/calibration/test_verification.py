"""Verify-then-refine: the default 4 fit poses are tested on 3 check poses (chi-square of
the residuals against the propagated parameter covariance plus the take noise); a sound
session passes at the stated false-alarm rate and is refitted on all 7; a bad check take or
an effect the model lacks is caught, named, and refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.identification import identify_verified
from cdprhost.calibration.planning import plan_poses
from cdprhost.calibration.verification import verify_checks
from cdprhost.cli.main import main
from cdprhost.effects.base import MotionContext
from cdprhost.sim.measurement import perturbed_geometry, simulate_observations
from cdprhost.sim.mocap_noise import MocapNoise
from cdprhost.sim.scenarios import hidden_truth, session_times
from cdprhost.sim.synthetic_session import write_synthetic_session

NOISE_MM = 0.03


@pytest.fixture(scope="module")
def plan(sim_model):
    return plan_poses(sim_model, 4, n_check=3)


def sound_session(sim_model, plan, seed):
    rng = np.random.default_rng(seed)
    truth = sim_model.with_geometry(perturbed_geometry(sim_model.geometry, rng, 2.0))
    return simulate_observations(truth, sim_model, plan.poses, noise_mm=NOISE_MM, rng=rng)


def test_sound_sessions_pass_at_the_stated_false_alarm_rate(sim_model, plan):
    """20 sound sessions at alpha = 0.01: at most 1 alarm (P(>= 2) = 1.7 % if the test holds
    its level), and the joint chi-square averages its 9 dof: the predicted covariance is
    neither too small (alarms) nor too large (no power)."""
    results = [
        identify_verified(sound_session(sim_model, plan, seed), sim_model, plan.roles)
        for seed in range(100, 120)
    ]
    verdicts = [r.verification.verdict for r in results if r.verification]
    assert len(verdicts) == 20 and verdicts.count("inconsistent") <= 1, verdicts
    chi2 = np.array([r.verification.chi2 for r in results if r.verification])
    assert all(r.verification.dof == 9 for r in results if r.verification)
    assert 6.5 < chi2.mean() < 12.0, chi2
    passed = [r for r in results if r.verification and r.verification.consistent]
    assert all(r.ok and r.poses_used == 7 and r.verification.refined for r in passed)
    assert all(r.verification.refined_rms_mm < 0.7 * r.verification.fit_only_rms_mm for r in passed)


def test_a_biased_check_take_is_caught_and_named(sim_model, plan):
    obs = sound_session(sim_model, plan, 7)
    assert identify_verified(obs, sim_model, plan.roles).verification.consistent
    k = int(np.flatnonzero(np.array(plan.roles) == "check")[1])
    obs.measured[k] += np.array([0.5, 0.0, 0.0])  # the effector was bumped 0.5 mm in that take
    r = identify_verified(obs, sim_model, plan.roles)
    v = r.verification
    assert v is not None and v.verdict == "inconsistent" and v.suspects == (k + 1,)
    assert not r.ok and r.poses_used == 4 and not v.refined  # the 4-pose fit, not refined
    text = " ".join(r.problems())
    assert f"pose {k + 1} off by" in text and "bad take" in text


@pytest.mark.parametrize("effect", ["cable_elasticity", "drive_scale", "backlash"])
def test_an_effect_the_model_lacks_is_caught(sim_model, plan, effect):
    for seed in range(3):
        rng = np.random.default_rng(seed)
        truth = hidden_truth(sim_model, rng, effect)
        obs = simulate_observations(truth, sim_model, plan.poses, noise_mm=NOISE_MM, rng=rng)
        r = identify_verified(obs, sim_model, plan.roles)
        assert r.verification is not None and r.verification.verdict == "inconsistent", (
            effect,
            seed,
        )
        assert not r.ok and "cdprhost diagnose" in " ".join(r.problems())


def test_the_test_uses_the_correlated_prediction_covariance():
    """Two check poses whose predictions share one uncertain parameter: a common offset along
    it is expected (consistent), the same size in opposite directions is not."""
    jac = np.zeros((2, 3, 12))
    jac[:, 0, 0] = 1.0
    cov = np.diag([1.0] + [1e-6] * 11)
    same = verify_checks(np.array([[2.0, 0, 0], [2.0, 0, 0]]), [0.1, 0.1], jac, cov, [5, 6])
    opposite = verify_checks(np.array([[2.0, 0, 0], [-2.0, 0, 0]]), [0.1, 0.1], jac, cov, [5, 6])
    assert same.consistent and same.dof == 6
    assert opposite.verdict == "inconsistent" and opposite.p_value < 1e-6
    assert verify_checks(np.zeros((0, 3)), [], np.zeros((0, 3, 12)), cov, []).verdict == "untested"


REALISM = MocapNoise(
    jitter_mm=0.2, correlation_s=0.015, settle_mm=0.5, settle_decay_s=0.2, gap_fraction=0.03
)


def realistic_session(path, sim_model, plan, bias_at=None):
    """A session folder on realistic takes; ``bias_at``: a check row whose take is 0.5 mm off."""
    rng = np.random.default_rng(5)
    truth = sim_model.with_geometry(perturbed_geometry(sim_model.geometry, rng, 2.0))
    s_cmd, dirs = commanded_path(sim_model, plan.poses)
    times = session_times(len(plan.poses), rng)
    actual = truth.fk(s_cmd, MotionContext(t_s=times, directions=dirs))
    if bias_at is not None:
        actual[bias_at] += np.array([0.0, 0.5, 0.0])
    return write_synthetic_session(
        path,
        actual,
        plan.poses,
        s_cmd,
        times,
        dirs.astype(int),
        "paper-simulation",
        noise_mm=0.0,
        n_frames=720,
        rate_hz=240.0,
        realism=REALISM,
        roles=plan.roles,
        seed=6,
    )


def test_cli_reports_the_verification_and_refuses_a_disagreeing_check_pose(
    tmp_path, sim_model, plan, capsys
):
    out, rep = tmp_path / "cal.toml", tmp_path / "r.json"
    args = ["--profile", "paper-simulation", "--out", str(out), "--json", str(rep)]
    good = realistic_session(tmp_path / "good", sim_model, plan)
    assert main(["calibrate", "identify", str(good), *args]) == 0
    data = json.loads(rep.read_text())
    v = data["verification"]
    assert v["verdict"] == "consistent" and v["dof"] == 9 and v["refined"] and data["ok"]
    assert {"pose", "residual_mm", "predicted_sigma_mm", "chi2", "dof", "p_value"} <= set(
        v["checks"][0]
    )
    assert data["poses_used"] == 7 and out.exists()
    text = capsys.readouterr().out
    assert "CONSISTENT" in text and "refined on fit + check poses" in text
    assert main(["calibrate", "identify", str(good), *args, "--no-refine"]) == 0
    assert json.loads(rep.read_text())["poses_used"] == 4
    out.unlink()

    k = int(np.flatnonzero(np.array(plan.roles) == "check")[0])
    bad = realistic_session(tmp_path / "bad", sim_model, plan, bias_at=k)
    capsys.readouterr()
    assert main(["calibrate", "identify", str(bad), *args]) == 1
    data = json.loads(rep.read_text())
    assert data["ok"] is False and data["verification"]["verdict"] == "inconsistent"
    assert data["verification"]["suspects"] == [k + 1] and not out.exists()
    err = capsys.readouterr().err
    assert f"pose {k + 1} off by" in err and "no profile written" in err
    assert main(["calibrate", "identify", str(bad), *args, "--force"]) == 0
    assert out.exists() and json.loads(rep.read_text())["forced"] is True
