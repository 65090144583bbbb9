"""Camera takes judged on the camera's own noise: on a rendered session no sound take is
refused as creep (a frame's B scatters several times more along the line of sight than
across it, and a few frames cannot show that), a take whose effector creeps 1.5 mm is
still refused as drift, naming the camera's noise, and one whose effector shakes by 0.3 mm
(far below the motion-capture spread cap of 1 mm) as spread."""

from __future__ import annotations

import pytest

from cdprhost.calibration.planning import candidate_poses, plan_poses
from cdprhost.calibration.session import load_session
from cdprhost.calibration.session_identification import measure_any
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import write_camera_session
from tests.calibration.conftest import paper_truth_geometry

pytestmark = pytest.mark.slow  # a rendered session of 10 poses, 4 frames each


@pytest.fixture(scope="module")
def measured(sim_model, tmp_path_factory):
    rig = rig_for_size((960, 540))
    cand = candidate_poses(sim_model)
    poses = plan_poses(sim_model, 10, candidates=cand[rig.visible(cand)], seed=3).poses
    truth = sim_model.with_geometry(paper_truth_geometry())
    s = write_camera_session(
        tmp_path_factory.mktemp("creep") / "s",
        truth,
        sim_model,
        poses,
        rig=rig,
        intrinsics="truth",
        frames_per_take=4,
        take_creep_mm={4: (1.2, -0.6, 0.7)},
        take_shake_mm={7: 0.3},
        seed=3,
    )
    return measure_any(load_session(s.directory), sim_model)


def test_only_the_creeping_and_the_shaking_takes_are_refused_and_why(measured):
    why = [r.message for r in measured.rejected]
    assert [(r.pose, r.reason) for r in measured.rejected] == [(4, "drift"), (7, "spread")], why
    assert "against the camera's frame noise" in measured.rejected[0].message
    assert "camera's frame noise predicts" in measured.rejected[1].message
    assert len(measured) == 8
