"""The session-level camera fit on analytic corners (truth projected, per-take static
detector bias and frame noise): accuracy against the truth, the noise model against the
realised errors, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.camera import Intrinsics, effector_positions, fit_session
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.positions import FrameQuality, without_stray_corners
from cdprhost.calibration.camera.session_fit import TakeDetections
from cdprhost.calibration.camera.take_drift import camera_drift
from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.identification import identify
from cdprhost.calibration.planning import plan_poses
from cdprhost.calibration.pose_noise import camera_noise
from cdprhost.calibration.trust import DEFAULT_TRUST
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.sim.scenarios import hidden_truth
from tests.calibration_camera.scene import analytic_takes, make_scene, workspace_rms


def calibrated(truth: Intrinsics, f_error: float = 0.002, k1_error: float = 0.005) -> Intrinsics:
    """What a decent calibration leaves: focal length 0.2 % off, k1 a little off, with the
    (optimistic) std calibrateCamera reports."""
    v = truth.vector.copy()
    v[:2] *= 1 + f_error
    v[4] += k1_error
    std = np.r_[v[:2] * 0.0005, 0.3, 0.3, 0.002, 0.005, np.nan, np.nan, np.nan]
    return Intrinsics.from_vector(v, truth.image_size, std=std)


@pytest.fixture(scope="module")
def session(sim_model):
    rng = np.random.default_rng(5)
    truth = hidden_truth(sim_model, rng, None)
    poses = plan_poses(sim_model, 15, seed=5).poses
    s_cmd, _ = commanded_path(sim_model, poses)
    actual = truth.fk(s_cmd)
    scene = make_scene()
    takes = analytic_takes(scene, actual, 4, rng)
    return truth, scene, takes, s_cmd, actual


def identified(fit, s_cmd, model, limits=DEFAULT_TRUST):
    noise = camera_noise(
        fit.covariances,
        np.zeros(len(s_cmd)),
        None,
        fit.common_covariance,
        fit.geometry_covariance_extra,
    )
    obs = Observations(fit.positions, s_cmd, sigma_mm=noise.sigma_mm, covariance=noise.covariance)
    return identify(obs, model, noise=noise, limits=limits)


def test_joint_refinement_beats_the_camera_alone(session, sim_model):
    truth, scene, takes, s_cmd, actual = session
    intr = calibrated(scene.intrinsics)
    grid = workspace_grid(sim_model)
    alone = fit_session(takes, scene.setup, intr)
    joint = fit_session(takes, scene.setup, intr, s_cmd, sim_model)
    rms_alone = workspace_rms(truth, identified(alone, s_cmd, sim_model).model, grid)
    result = identified(joint, s_cmd, sim_model)
    rms_joint = workspace_rms(truth, result.model, grid)
    # the focal length is pulled back towards the truth by the robot's motion
    f_err = abs(joint.intrinsics.vector[0] / scene.intrinsics.vector[0] - 1)
    assert f_err < 0.0008, f_err
    assert "f" in joint.refined
    assert rms_joint <= 0.5, rms_joint
    assert rms_joint < 0.6 * rms_alone, (rms_joint, rms_alone)
    # the trust gate's prediction holds within a factor 1.5, and it trusts the result
    ratio = result.predicted_workspace_rms_mm / rms_joint
    assert 1 / 1.5 <= ratio <= 1.5, (result.predicted_workspace_rms_mm, rms_joint)
    assert result.ok, result.problems()


def test_pose_covariance_is_anisotropic_along_the_line_of_sight(session, sim_model):
    _, scene, takes, s_cmd, actual = session
    fit = fit_session(takes, scene.setup, scene.intrinsics, s_cmd, sim_model)
    eye = -scene.cam_rot.T @ scene.cam_t
    for b, cov in zip(fit.positions, fit.covariances):
        w, v = np.linalg.eigh(cov)
        sight = (b - eye) / np.linalg.norm(b - eye)
        assert abs(v[:, -1] @ sight) > 0.9  # the worst direction is depth
        assert np.sqrt(w[-1] / w[0]) > 2.0
    # and the predicted size matches the realised errors
    err = fit.positions - actual
    predicted = np.sqrt(np.mean(np.trace(fit.covariances, axis1=1, axis2=2)))
    realised = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    assert 0.5 < realised / predicted < 2.0, (realised, predicted)


def test_per_frame_positions_are_worse_than_the_session_fit(session, sim_model):
    _, scene, takes, s_cmd, actual = session
    fit = fit_session(takes, scene.setup, scene.intrinsics)
    frame = np.array(
        [
            np.nanmean(
                effector_positions(
                    list(t.reference), list(t.effector), scene.setup, scene.intrinsics
                ).positions,
                axis=0,
            )
            for t in takes
        ]
    )
    e_frame = np.sqrt(np.mean((frame - actual) ** 2))
    e_session = np.sqrt(np.mean((fit.positions - actual) ** 2))
    assert e_session < e_frame


def test_clustered_poses_are_refused_by_the_trust_gate(sim_model):
    rng = np.random.default_rng(9)
    truth = hidden_truth(sim_model, rng, None)
    centre = np.array([0.0, 0.0, 200.0])
    poses = centre + rng.uniform(-10, 10, (15, 3))
    s_cmd, _ = commanded_path(sim_model, poses)
    scene = make_scene()
    takes = analytic_takes(scene, truth.fk(s_cmd), 4, rng)
    fit = fit_session(takes, scene.setup, scene.intrinsics, s_cmd, sim_model)
    result = identified(fit, s_cmd, sim_model)
    assert not result.ok
    assert any("predicted workspace error" in p for p in result.problems()), result.problems()


def test_reference_board_never_seen_is_refused_naming_it(session):
    _, scene, takes, _, _ = session
    blind = [type(t)(tuple(None for _ in t.reference), t.effector) for t in takes]
    with pytest.raises(ValueError, match="reference board"):
        fit_session(blind, scene.setup, scene.intrinsics)


def test_frames_without_the_effector_board_are_skipped_and_named(session):
    _, scene, takes, _, _ = session
    t0 = takes[0]
    hidden = type(t0)(t0.reference, (None,) + t0.effector[1:])
    fit = fit_session([hidden, *takes[1:]], scene.setup, scene.intrinsics)
    assert fit.frame_skipped[0][0] == "effector board not found"
    assert all(s == "" for s in fit.frame_skipped[0][1:])
    assert np.isnan(fit.frame_positions[0][0]).all()
    assert np.isfinite(fit.positions[0]).all()


def test_a_frame_that_lost_a_marker_is_not_taken_for_creep(sim_model):
    """Each corner's error has a part that stays for the whole take (the picture at that
    place); a frame that lost three corners must be compared with its take's other frames
    on the corners they share, or that part shows as a jump along the line of sight."""
    rng = np.random.default_rng(11)
    poses = plan_poses(sim_model, 12, seed=11).poses
    s_cmd, _ = commanded_path(sim_model, poses)
    scene = make_scene()
    takes = analytic_takes(scene, sim_model.fk(s_cmd), 3, rng, sigma_px=0.03, bias_px=0.08)
    lost = []
    for take in takes:
        first = take.effector[0]
        assert first is not None
        keep = np.ones(len(first.ids), bool)
        keep[:3] = False  # the corners around one marker
        cut = BoardDetection(
            first.ids[keep], first.corners_px[keep], first.n_markers - 1, 1000.0, first.image_size
        )
        lost.append(TakeDetections(take.reference, (cut, *take.effector[1:])))
    fit = fit_session(lost, scene.setup, scene.intrinsics, s_cmd, sim_model)
    p = [
        camera_drift(fit.frame_positions[k], np.arange(3) / 30.0, fit.frame_noise_covariances[k]).p
        for k in range(len(lost))
    ]
    assert min(p) > 1e-3, p
    # and the test still sees a creep of 1 mm in those takes
    crept = [
        fp + np.linspace(-0.5, 0.5, 3)[:, None] * np.array([0.0, 0.0, 1.0])
        for fp in fit.frame_positions
    ]
    caught = [
        camera_drift(c, np.arange(3) / 30.0, fit.frame_noise_covariances[k]).p < 1e-3
        for k, c in enumerate(crept)
    ]
    assert np.mean(caught) > 0.8, caught


def test_a_reference_board_partly_hidden_by_the_effector_costs_neither_the_take_nor_the_frame(
    session, sim_model
):
    """The effector in front of the reference board pulls the corners beside its edge a few
    pixels off: those corners are dropped, the frame keeps its effector position, and the
    session's camera pose takes no corner from it."""
    _, scene, takes, s_cmd, _ = session
    hidden = []
    for k, take in enumerate(takes):
        if k != 4:
            hidden.append(take)
            continue
        refs = []
        for d in take.reference:
            assert d is not None
            px = d.corners_px.copy()
            px[:4] += (8.0, -6.0)  # four corners beside the effector's edge
            refs.append(BoardDetection(d.ids, px, d.n_markers, d.sharpness, d.image_size))
        hidden.append(TakeDetections(tuple(refs), take.effector, take.times_s))
    clean = fit_session(takes, scene.setup, scene.intrinsics, s_cmd, sim_model)
    fit = fit_session(hidden, scene.setup, scene.intrinsics, s_cmd, sim_model)
    assert fit.frame_skipped[4] == ("",) * len(takes[4].reference), fit.frame_skipped[4]
    assert np.isfinite(fit.positions[4]).all()
    # the frames' own stray corners (pulled 10 px) do not reach the camera pose: what
    # changes is four frames fewer in it, well within the poses' own noise
    d = np.linalg.norm(fit.positions - clean.positions, axis=1)
    sd = np.sqrt(np.trace(clean.covariances, axis1=1, axis2=2))
    assert np.all(d < 0.5 * sd), (d, sd)


def test_stray_corners_are_dropped_up_to_a_quarter_of_the_board():
    scene = make_scene()
    board = scene.setup.reference.board
    ref, _ = scene.corners(np.array([0.0, 0.0, 200.0]))
    ids = np.arange(len(ref))
    few = ref.copy()
    few[[3, 10]] += 5.0
    det = BoardDetection(ids, few, 12, 1000.0, scene.intrinsics.image_size)
    kept = without_stray_corners(det, board, scene.intrinsics, FrameQuality())
    assert kept is not None and sorted(set(ids) - set(kept.ids)) == [3, 10]
    many = ref.copy()
    many[: len(ref) // 2] += np.random.default_rng(0).normal(0, 5.0, (len(ref) // 2, 2))
    det = BoardDetection(ids, many, 12, 1000.0, scene.intrinsics.image_size)
    assert without_stray_corners(det, board, scene.intrinsics, FrameQuality()) is det
