"""`calibrate identify` on rendered camera sessions: a sound session is trusted; a take
whose effector board is lost in blur is refused naming the board and the frames; a session
in which a board is never found (too dark) is refused, naming it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.calibration.planning import candidate_poses, plan_poses
from cdprhost.cli.main import main
from cdprhost.sim.camera.imaging import Imaging
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import write_camera_session
from tests.calibration.conftest import paper_truth_geometry

ARGS = ["--profile", "paper-simulation"]
pytestmark = pytest.mark.slow  # rendered sessions of 10 poses (about a minute each)


@pytest.fixture(scope="module")
def rig():
    return rig_for_size((960, 540))


@pytest.fixture(scope="module")
def poses(rig, sim_model):
    cand = candidate_poses(sim_model)
    return plan_poses(sim_model, 10, candidates=cand[rig.visible(cand)]).poses


def _session(folder, rig, sim_model, poses, **options):
    truth = sim_model.with_geometry(paper_truth_geometry())
    return write_camera_session(
        folder, truth, sim_model, poses, rig=rig, intrinsics="truth", frames_per_take=3, **options
    )


@pytest.fixture(scope="module")
def blurred(rig, sim_model, poses, tmp_path_factory):
    """A session whose third take is smeared (the effector board lost in it), identified."""
    tmp = tmp_path_factory.mktemp("blur")
    blur = Imaging(motion_px=40.0, motion_deg=30.0)
    s = _session(tmp / "s", rig, sim_model, poses, take_imaging={3: blur})
    report = tmp / "r.json"
    args = ["calibrate", "identify", str(s.directory), *ARGS, "--out", str(tmp / "c.toml")]
    code = main([*args, "--json", str(report)])
    return code, json.loads(report.read_text())


def test_a_blurred_take_is_refused_naming_the_board_and_frames(blurred, poses):
    _, data = blurred
    refused = [r for r in data["rejected"] if r.startswith("pose 3 ")]
    assert refused, data["rejected"]
    assert "board" in refused[0] and "frame_1.jpg" in refused[0]
    assert data["poses_used"] == len(poses) - 1


def test_the_rest_of_the_session_is_identified_and_trusted(blurred):
    code, data = blurred
    assert code == 0 and data["ok"] is True, data.get("problems")
    assert data["rms_after_mm"] < 1.5 and np.isfinite(data["predicted_workspace_rms_mm"])


def test_a_board_never_found_refuses_the_session_naming_it(rig, sim_model, poses, tmp_path, capsys):
    dark = Imaging(light=0.0004)
    s = _session(
        tmp_path / "s", rig, sim_model, poses[:4], take_imaging=dict.fromkeys(range(1, 5), dark)
    )
    code = main(
        ["calibrate", "identify", str(s.directory), *ARGS, "--out", str(tmp_path / "c.toml")]
    )
    err = capsys.readouterr().err
    assert code in (1, 2) and not (tmp_path / "c.toml").exists()
    assert "board" in err and "frame_1.jpg" in err
