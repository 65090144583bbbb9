"""The trust gate (issue 11, deliver 3): predicted workspace error from the parameter
covariance, refusal (exit 1, ok false, no profile) unless --force, named weak combinations."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.identification import calibrated_profile, identify
from cdprhost.calibration.planning import TABLE1_POSES, plan_poses
from cdprhost.calibration.trust import TrustLimits, workspace_sigma
from cdprhost.cli.main import main
from cdprhost.errors import JobFailed
from cdprhost.kinematics import CableGeometry
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.sim.measurement import achieved_points, perturbed_geometry, simulate_observations
from cdprhost.sim.mocap_noise import MocapNoise, vary
from cdprhost.sim.scenarios import session_times
from cdprhost.sim.synthetic_session import write_measured_session

REALISM = MocapNoise(
    jitter_mm=0.2, correlation_s=0.015, settle_mm=0.5, settle_decay_s=0.2, gap_fraction=0.03
)


@pytest.fixture(scope="module")
def truth(sim_model):
    return sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(31), 2.0)
    )


def identify_cli(session, tmp_path, *extra):
    out, rep = tmp_path / "cal.toml", tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "identify",
            str(session),
            "-p",
            "paper-simulation",
            "--out",
            str(out),
            "--json",
            str(rep),
            *extra,
        ]
    )
    return code, out, json.loads(rep.read_text())


def test_coplanar_four_poses_are_refused_with_the_reason(tmp_path, sim_model, truth, capsys):
    """The paper's Table 1: four close poses in the plane z = 110."""
    write_measured_session(
        tmp_path / "s",
        truth,
        sim_model,
        TABLE1_POSES,
        session_times(4, np.random.default_rng(1)),
        realism=REALISM,
        seed=2,
    )
    code, out, data = identify_cli(tmp_path / "s", tmp_path)
    text = capsys.readouterr()
    assert code == 1 and not out.exists() and data["ok"] is False
    assert data["predicted_workspace_max_mm"] > 1.0
    assert data["predicted_workspace_rms_mm"] <= data["predicted_workspace_max_mm"]
    problems = " ".join(data["problems"])
    assert "noise cannot be estimated" in problems
    assert "predicted workspace error up to" in problems and "exceeds 1 mm" in problems
    assert re.search(r"weakly observed parameter combination\(s\): [+-]0\.\d\d\*", problems)
    assert "NOT TRUSTED" in text.out and "calibration refused; no profile written" in text.err
    # --force writes it anyway; the report still says it is not trusted
    code, out, data = identify_cli(tmp_path / "s", tmp_path, "--force")
    assert code == 0 and out.exists() and data["ok"] is False and data["forced"] is True


def test_planned_session_is_trusted_and_the_prediction_matches_reality(
    tmp_path, sim_model, truth, capsys
):
    plan = plan_poses(sim_model, 8, n_check=2)
    write_measured_session(
        tmp_path / "s",
        truth,
        sim_model,
        plan.poses,
        session_times(len(plan.poses), np.random.default_rng(3)),
        realism=REALISM,
        rate_hz=240,
        roles=plan.roles,
        seed=4,
    )
    code, out, data = identify_cli(tmp_path / "s", tmp_path)
    assert code == 0 and data["ok"] is True and data["poses_used"] == 10  # verified, refined
    assert data["verification"]["verdict"] == "consistent" and data["verification"]["refined"]
    assert 0 < data["predicted_workspace_rms_mm"] < data["predicted_workspace_max_mm"] < 0.3
    assert "TRUSTED" in capsys.readouterr().out
    from cdprhost.kinematics import MachineModel
    from cdprhost.profile import load_profile

    cal = MachineModel.from_profile(load_profile(out))
    grid = workspace_grid(sim_model)
    achieved = np.linalg.norm(achieved_points(truth, cal, grid) - grid, axis=1)
    rms = float(np.sqrt(np.mean(achieved**2)))
    assert rms < 3 * data["predicted_workspace_rms_mm"]  # a single draw of an honest prediction


def test_refused_takes_are_listed_as_pose_take_reason_message(tmp_path, sim_model, truth):
    plan = plan_poses(sim_model, 6)
    rng = np.random.default_rng(5)
    noises = [vary(REALISM, rng) for _ in plan.poses]
    noises[2] = dataclasses.replace(noises[2], creep_mm=0.5)
    write_measured_session(
        tmp_path / "s",
        truth,
        sim_model,
        plan.poses,
        session_times(6, rng),
        realism=noises[0],
        seed=6,
    )
    # re-write the third take with a creep of 0.5 mm over the take
    from cdprhost.calibration.mocap.readers import read_take, write_take
    from cdprhost.sim.synthetic_session import synthesize_take

    take = read_take(tmp_path / "s" / "takes" / "pose_0003.csv")
    centre = np.nanmean(take.positions, axis=0)  # mocap world
    crept = synthesize_take(
        [0.0, 0.0, 200.0], realism=noises[2], n_frames=take.n_frames, rng=rng
    )  # its motion only
    moved = crept.positions - np.nanmean(crept.positions, axis=0) + centre
    write_take(
        tmp_path / "s" / "takes" / "pose_0003.csv",
        dataclasses.replace(take, positions=moved),
        "motive-csv",
    )
    code, _, data = identify_cli(tmp_path / "s", tmp_path)
    assert len(data["rejected"]) == 1
    assert re.match(
        r"pose 3 \(takes/pose_0003\.csv\): drift: .*effector crept 0\.\d+ mm", data["rejected"][0]
    )
    assert data["poses_used"] == 5


def test_prediction_is_the_covariance_carried_to_the_workspace(sim_model, truth):
    plan = plan_poses(sim_model, 6)
    obs = simulate_observations(
        truth, sim_model, plan.poses, noise_mm=0.05, rng=np.random.default_rng(7)
    )
    r = identify(obs, sim_model)
    grid = workspace_grid(sim_model)
    sigma = workspace_sigma(r.geometry, r.covariance, grid)
    assert r.predicted_workspace_max_mm == pytest.approx(sigma.max())
    # Monte Carlo of the same covariance: the RMS position error matches the prediction
    rng = np.random.default_rng(8)
    dq = rng.multivariate_normal(np.zeros(12), r.covariance, 400)
    from cdprhost.kinematics.jacobian import identification_jacobian

    j0 = identification_jacobian(grid, r.geometry).reshape(-1, 3, 12)
    err = np.einsum("nip,sp->sni", j0, dq)
    assert np.sqrt(np.mean(err**2) * 3) == pytest.approx(r.predicted_workspace_rms_mm, rel=0.1)


def test_warns_between_the_limits_and_refuses_above(sim_model, truth):
    plan = plan_poses(sim_model, 5)
    exact = simulate_observations(truth, sim_model, plan.poses, noise_mm=0.0)
    obs = Observations(exact.measured, exact.sliders, exact.t_s, exact.directions, 0.01)
    r1 = identify(obs, sim_model)
    worst = r1.predicted_workspace_max_mm
    assert r1.ok and not r1.warnings()
    warn = identify(
        obs, sim_model, limits=TrustLimits(max_workspace_mm=10 * worst, warn_workspace_mm=worst / 2)
    )
    assert warn.ok and any("above" in w for w in warn.warnings())
    refuse = identify(obs, sim_model, limits=TrustLimits(max_workspace_mm=worst / 2))
    assert not refuse.ok and "exceeds" in refuse.problems()[0]


def test_a_geometry_the_profile_refuses_is_a_clear_error(sim_profile, sim_model, truth):
    plan = plan_poses(sim_model, 6)
    obs = simulate_observations(truth, sim_model, plan.poses, noise_mm=0.01)
    r = identify(obs, sim_model)
    above = sim_model.geometry.outlets.copy()
    above[:, 2] = 500.0  # outlets above the build volume
    bad = dataclasses.replace(r, geometry=CableGeometry(above, sim_model.geometry.initial_lengths))
    with pytest.raises(JobFailed, match="not a valid profile; no profile written") as err:
        calibrated_profile(sim_profile, bad)
    assert "outlet" in str(err.value).lower() and err.value.exit_code == 1
