"""The wizard with a camera, end to end against the embedded simulated device and the
simulated camera: both boards checked before the first move, only poses the camera sees,
a blurred take refused and captured again, the trust gate, a profile."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.calibration.camera.capture import CameraTakes
from cdprhost.calibration.camera.visibility import visible_mask
from cdprhost.calibration.planning import candidate_poses
from cdprhost.calibration.wizard import CalibrationWizard, WizardOptions
from cdprhost.cli.main import main
from cdprhost.errors import InputError
from cdprhost.machine import Machine
from cdprhost.profile import load_profile, save_profile
from cdprhost.sim.camera.device import VirtualCamera
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import camera_config, true_intrinsics
from cdprhost.sim.embedded import open_embedded
from tests.calibration.conftest import paper_truth_geometry

SIZE = (960, 540)


@pytest.fixture()
def truth(sim_profile):
    g = paper_truth_geometry()
    return sim_profile.with_geometry(g.outlets, g.initial_lengths, name="hidden-truth")


@pytest.fixture(scope="module")
def rig():
    return rig_for_size(SIZE)


def test_first_look_sees_both_boards_and_plans_only_visible_poses(rig, sim_model, tmp_path):
    camera = VirtualCamera(sim_model, rig, supersample=1)
    intr = true_intrinsics(rig)
    takes = CameraTakes(camera, tmp_path, rig.setup, intr, frames=2, log=lambda m: None)
    view = takes.first_look()
    np.testing.assert_allclose(view.position, rig.camera.position, atol=15.0)
    cand = candidate_poses(sim_model)
    planned = visible_mask(cand, view, rig.setup)
    truth_mask = rig.visible(cand)
    assert planned.mean() > 0.1 and (planned == truth_mask).mean() > 0.95


def test_first_look_refuses_when_a_board_is_hidden(rig, sim_model, tmp_path):
    camera = VirtualCamera(sim_model, rig.with_imaging(light=0.0005), supersample=1)
    takes = CameraTakes(camera, tmp_path, rig.setup, true_intrinsics(rig), log=lambda m: None)
    with pytest.raises(InputError, match="board"):
        takes.first_look()


def test_wizard_refuses_a_blurred_take_and_captures_it_again(rig, truth, sim_model, tmp_path):
    from cdprhost.kinematics import MachineModel

    true_model = MachineModel.from_profile(truth)
    camera = VirtualCamera(true_model, rig, supersample=1, blurred_settles={1})
    intr = true_intrinsics(rig)
    logs: list[str] = []
    takes = CameraTakes(camera, tmp_path / "cap", rig.setup, intr, frames=3, log=logs.append)
    cand = candidate_poses(sim_model)
    link = open_embedded(observer=camera)
    camera.attach_record(link.device.record)
    try:
        profile = load_profile("paper-simulation")
        wiz = CalibrationWizard(
            tmp_path / "s",
            profile,
            Machine(link, profile, sim_model, settle_s=0.3),
            takes,
            camera=camera_config(rig),
            intrinsics=intr,
            candidates=cand[visible_mask(cand, takes.first_look(), rig.setup)],
            options=WizardOptions(n_poses=4, n_check=0, max_augment_rounds=0),
            log=logs.append,
        )
        wiz.step()  # move to the first pose
        wiz.step()  # its take: blurred, refused
        assert any("take refused" in m and "board" in m for m in logs), logs
        wiz.step()  # move again
        wiz.step()  # a sharp take
        assert any(m.startswith("recorded pose 1/") for m in logs), logs
    finally:
        link.close()
    assert (tmp_path / "s" / "takes" / "pose_0001" / "frame_1.jpg").is_file()


@pytest.mark.slow
def test_wizard_cli_with_the_simulated_camera_ends_trusted(truth, tmp_path, capsys):
    truth_path = tmp_path / "truth.toml"
    save_profile(truth, truth_path)
    report = tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "wizard",
            "--profile",
            "paper-simulation",
            "--camera",
            "sim",
            "--sim-camera",
            f"{SIZE[0]}x{SIZE[1]}",
            "--sim-truth",
            str(truth_path),
            "--session",
            str(tmp_path / "s"),
            "--poses",
            "10",
            "--frames",
            "3",
            "--out",
            str(tmp_path / "cal.toml"),
            "--json",
            str(report),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out[-3000:]
    assert "candidate poses are in good view" in out and "reference board:" in out
    data = json.loads(report.read_text())
    assert data["ok"] is True
    assert load_profile(tmp_path / "cal.toml").calibration is not None
    assert (tmp_path / "s" / "camera.toml").is_file()


def _wizard(tmp_path, *extra):
    return main(
        [
            "calibrate",
            "wizard",
            "--profile",
            "paper-simulation",
            "--session",
            str(tmp_path / "s"),
            *extra,
        ]
    )


def test_a_real_camera_needs_its_boards_and_intrinsics(rig, tmp_path, capsys):
    import cv2

    from cdprhost.calibration.camera.config import intrinsics_toml
    from cdprhost.calibration.session import SessionConfig
    from cdprhost.calibration.session_writer import session_toml

    assert _wizard(tmp_path, "--camera", str(tmp_path / "none.avi")) == 2
    assert "cannot open camera" in capsys.readouterr().err
    video = tmp_path / "cam.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 30.0, SIZE)
    writer.write(np.full((SIZE[1], SIZE[0], 3), 128, np.uint8))
    writer.release()
    assert _wizard(tmp_path, "--camera", str(video)) == 2
    assert "--camera-config" in capsys.readouterr().err
    boards = tmp_path / "boards.toml"
    cfg = SessionConfig.model_validate({"session": {"profile": "p"}, "camera": camera_config(rig)})
    boards.write_text(session_toml(cfg).replace("square_mm = 35.0", "square_mm = -3.0", 1))
    assert _wizard(tmp_path, "--camera", str(video), "--camera-config", str(boards)) == 2
    assert "camera.reference_board.square_mm" in capsys.readouterr().err
    boards.write_text(session_toml(cfg))
    assert _wizard(tmp_path, "--camera", str(video), "--camera-config", str(boards)) == 2
    assert "--camera-intrinsics" in capsys.readouterr().err
    intr = tmp_path / "camera.toml"
    intr.write_text(intrinsics_toml(true_intrinsics(rig)))
    args = (
        "--camera",
        str(video),
        "--camera-config",
        str(boards),
        "--camera-intrinsics",
        str(intr),
    )
    assert _wizard(tmp_path, *args) == 2  # a grey picture: no board, nothing moves
    err = capsys.readouterr().err
    assert "reference and the effector board" in err and "before the first move" in err
    assert not (tmp_path / "s" / "takes").exists() or not any((tmp_path / "s" / "takes").iterdir())
