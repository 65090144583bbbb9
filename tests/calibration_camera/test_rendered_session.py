"""Acceptance on a rendered camera session (the simulated camera of cdprhost/sim): 1920x1080,
a 70 degree lens at 0.7 m, 15 fit poses of 3 frames each, blur, noise and JPEG, intrinsics
calibrated from rendered views (not the truth). The identified profile's workspace error
against the truth is at most 0.5 mm and the trust gate predicts it within a factor 1.5; a
take whose pictures are drowned in blur is refused naming the board and the frames."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.planning import candidate_poses, plan_poses
from cdprhost.calibration.session_identification import identify_session
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.sim.camera.imaging import Imaging
from cdprhost.sim.camera.scene import standard_rig
from cdprhost.sim.camera.session import write_camera_session
from cdprhost.sim.measurement import perturbed_geometry
from tests.calibration_camera.scene import workspace_rms


@pytest.mark.slow
@pytest.mark.timeout(1800)  # renders 48 frames and 18 calibration views at 1080p
def test_rendered_session_meets_the_target(tmp_path, sim_model):
    truth = sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(101))
    )
    rig = standard_rig()
    cand = candidate_poses(sim_model)
    poses = plan_poses(sim_model, 15, candidates=cand[rig.visible(cand)], seed=1).poses
    poses = np.vstack([poses, poses[:1] + [5.0, 5.0, 5.0]])  # pose 16: a blurred take
    write_camera_session(
        tmp_path / "s",
        truth,
        sim_model,
        poses,
        rig=rig,
        frames_per_take=3,
        intrinsics="calibrated",
        take_imaging={16: Imaging(defocus_px=9.0, light=0.2)},
        seed=1,
    )
    result = identify_session(tmp_path / "s", sim_model)
    assert [r.split(":")[0] for r in result.rejected] == ["pose 16 (takes/pose_0016)"]
    assert "board not seen well enough in" in result.rejected[0], result.rejected[0]
    assert result.poses_used == 15
    rms = workspace_rms(truth, result.model, workspace_grid(sim_model))
    assert rms <= 0.5, rms
    ratio = result.predicted_workspace_rms_mm / rms
    assert 1 / 1.5 <= ratio <= 1.5, (result.predicted_workspace_rms_mm, rms)
    assert result.ok, result.problems()


@pytest.mark.slow
@pytest.mark.timeout(1800)  # renders 45 frames and 20 calibration views at 1080p
def test_intrinsics_from_a_bowed_printed_board_meet_the_target(tmp_path, sim_model):
    """The session's intrinsics self-calibrated (by the reader, from the session's own
    views) from 20 views of a sheet bowed by 0.5 mm, one image corner never reached, views
    cut by the image's edge, two views without a findable board: 1080p at 0.75 m."""
    truth = sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(101))
    )
    rig = standard_rig(distance_mm=750.0)
    cand = candidate_poses(sim_model)
    poses = plan_poses(sim_model, 15, candidates=cand[rig.visible(cand)], seed=1).poses
    write_camera_session(
        tmp_path / "s",
        truth,
        sim_model,
        poses,
        rig=rig,
        frames_per_take=3,
        intrinsics="views",
        n_views=20,
        views_kind="printed",
        bow_mm=(0.5, 0.15),
        seed=1,
    )
    result = identify_session(tmp_path / "s", sim_model)
    rms = workspace_rms(truth, result.model, workspace_grid(sim_model))
    assert rms <= 0.5, rms
    assert result.ok, result.problems()
    assert not any("drift" in r for r in result.rejected), result.rejected
