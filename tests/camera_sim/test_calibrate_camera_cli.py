"""`cdprhost calibrate camera`: intrinsics from rendered views of a board; views that do not
cover the image or tilt enough are refused (exit 1) with the reason and what to add."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from cdprhost.calibration.camera.config import load_intrinsics
from cdprhost.cli.main import main
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import camera_config, true_intrinsics, write_views

BOARD = "9x6,25,18,DICT_5X5_250,150"


@pytest.fixture(scope="module")
def rig():
    return rig_for_size((640, 480))


@pytest.fixture(scope="module")
def good_views(rig, tmp_path_factory):
    return write_views(tmp_path_factory.mktemp("good"), rig, 14, supersample=1)


def test_good_views_give_intrinsics_close_to_the_truth(rig, good_views, tmp_path, capsys):
    out, report = tmp_path / "camera.toml", tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "camera",
            str(good_views),
            "--board",
            BOARD,
            "--out",
            str(out),
            "--json",
            str(report),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "reprojection error RMS" in text and "fx =" in text and "+-" in text
    data = json.loads(report.read_text())
    assert data["ok"] is True and data["rms_reprojection_px"] < 0.3
    assert data["coverage"]["corner_cells"] == 4
    got = load_intrinsics(out)
    truth = true_intrinsics(rig)
    assert got.image_size == (640, 480)
    assert abs(got.vector[0] / truth.vector[0] - 1) < 0.01  # focal length within 1 %
    assert np.isfinite(got.std[:4]).all()


def test_poor_coverage_is_refused_with_the_reason(rig, tmp_path, capsys):
    views = write_views(tmp_path / "poor", rig, 8, coverage="poor", supersample=1)
    out, report = tmp_path / "camera.toml", tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "camera",
            str(views),
            "--board",
            BOARD,
            "--out",
            str(out),
            "--json",
            str(report),
        ]
    )
    assert code == 1
    err = capsys.readouterr().err
    assert "refused" in err and not out.exists()
    data = json.loads(report.read_text())
    assert data["ok"] is False and data["coverage"]["reason"] and data["coverage"]["advice"]
    assert data["problems"]


def test_views_of_a_session_folder(rig, good_views, tmp_path):
    from cdprhost.calibration.session import SessionConfig
    from cdprhost.calibration.session_writer import session_toml

    session = tmp_path / "s"
    session.mkdir()
    shutil.copytree(good_views, session / "intrinsics")
    cfg = SessionConfig.model_validate(
        {"session": {"profile": "paper-simulation"}, "camera": camera_config(rig, "views")}
    )
    (session / "session.toml").write_text(session_toml(cfg))
    assert main(["calibrate", "camera", str(session), "--out", str(tmp_path / "c.toml")]) == 0


@pytest.mark.parametrize(
    ("board", "why"),
    [("9x6,25", "cannot read"), ("9x6,25,30", "marker_mm"), ("9x6,25,18,DICT_NOPE", "DICT_NOPE")],
)
def test_bad_board_is_a_usage_error(good_views, tmp_path, capsys, board, why):
    assert (
        main(
            ["calibrate", "camera", str(good_views), "--board", board, "--out", str(tmp_path / "c")]
        )
        == 2
    )
    assert why in capsys.readouterr().err


def test_live_views_from_the_simulated_camera(tmp_path, capsys):
    out, saved = tmp_path / "camera.toml", tmp_path / "views"
    args = ["calibrate", "camera", "--camera", "sim", "--sim-camera", "640x480", "--views", "12"]
    assert main([*args, "--out", str(out), "--save-views", str(saved)]) == 0
    text = capsys.readouterr().out
    assert "view 12/12" in text and "reprojection error RMS" in text
    assert len(list(saved.glob("view_*.png"))) == 12
    truth = true_intrinsics(rig_for_size((640, 480)))
    assert abs(load_intrinsics(out).vector[0] / truth.vector[0] - 1) < 0.01
