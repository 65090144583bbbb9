"""Camera session folders: the simulated writer's folders read back; bad [camera] tables,
camera.toml files and takes are refused naming the file, the key or the picture."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from cdprhost.calibration.camera.config import intrinsics_toml, load_intrinsics
from cdprhost.calibration.camera.takes import image_files, natural_key, read_frames
from cdprhost.calibration.session import load_session, load_session_config
from cdprhost.errors import InputError
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import true_intrinsics, write_camera_session

SPEC_TOML = """\
[session]
profile = "paper-simulation"

[camera]
intrinsics = "camera.toml"

[camera.reference_board]
dictionary = "DICT_5X5_250"
squares = [7, 5]
square_mm = 30.0
marker_mm = 22.0
first_marker_id = 0
origin = [-105.0, 75.0, 3.0]
rotation_deg = [180.0, 0.0, 0.0]

[camera.effector_board]
dictionary = "DICT_5X5_250"
squares = [5, 4]
square_mm = 16.0
marker_mm = 12.0
first_marker_id = 100
offset = [40.0, 36.0, 69.0]
"""

SPEC_CAMERA = """\
[camera]
image_size = [1920, 1080]
matrix = [[1400.0, 0.0, 960.0], [0.0, 1400.0, 540.0], [0.0, 0.0, 1.0]]
distortion = [-0.12, 0.05, 0.0, 0.0, 0.0]
rms_reprojection_px = 0.25
"""


@pytest.fixture(scope="module")
def small_session(tmp_path_factory, sim_model):
    poses = np.array([[0.0, 0.0, 200.0], [30.0, -20.0, 150.0], [-25.0, 10.0, 260.0]])
    d = tmp_path_factory.mktemp("cam") / "session"
    return write_camera_session(
        d,
        sim_model,
        sim_model,
        poses,
        rig=rig_for_size((640, 360)),
        intrinsics="truth",
        frames_per_take=2,
        supersample=1,
    )


def test_spec_example_reads(tmp_path):
    (tmp_path / "session.toml").write_text(SPEC_TOML)
    (tmp_path / "camera.toml").write_text(SPEC_CAMERA)
    cfg = load_session_config(tmp_path / "session.toml")
    assert cfg.mocap is None and cfg.camera is not None
    setup = cfg.camera.setup()
    assert setup.effector.offset == (40.0, 36.0, 69.0)
    np.testing.assert_allclose(setup.reference.rotation @ [0, 0, 1], [0, 0, -1], atol=1e-12)
    intr = load_intrinsics(tmp_path / "camera.toml")
    assert intr.image_size == (1920, 1080) and intr.rms_reprojection_px == 0.25
    again = tmp_path / "again.toml"
    again.write_text(intrinsics_toml(intr))
    np.testing.assert_array_equal(load_intrinsics(again).vector, intr.vector)


@pytest.mark.parametrize(
    ("edit", "where"),
    [
        (
            ('intrinsics = "camera.toml"', 'intrinsics = "camera.toml"\ncalibration_views = "v"'),
            "camera",
        ),
        (('intrinsics = "camera.toml"', 'calibration_views = "v"'), "calibration_board"),
        (("origin = [-105.0, 75.0, 3.0]\n", ""), "camera.reference_board.origin"),
        (("marker_mm = 12.0", "marker_mm = 20.0"), "camera.effector_board"),
        (("first_marker_id = 100", "first_marker_id = 10"), "marker ids"),
        (
            (
                'dictionary = "DICT_5X5_250"\nsquares = [5, 4]',
                'dictionary = "DICT_9X9"\nsquares = [5, 4]',
            ),
            "DICT_9X9",
        ),
        (
            (
                "[camera]\n",
                (
                    "[mocap]\nbase_markers = {a = [0, 0, 0], b = [9, 0, 0], c = [0, 9, 0]}\n"
                    'effector = {markers = ["e"]}\n[camera]\n'
                ),
            ),
            "exactly one",
        ),
    ],
)
def test_bad_camera_section_names_the_key(tmp_path, edit, where):
    (tmp_path / "session.toml").write_text(SPEC_TOML.replace(*edit, 1))
    with pytest.raises(InputError) as info:
        load_session_config(tmp_path / "session.toml")
    assert where in str(info.value) + " ".join(getattr(info.value, "problems", []) or [])


@pytest.mark.parametrize(
    ("edit", "where"),
    [
        (("image_size = [1920, 1080]\n", ""), "camera.image_size"),
        (("[0.0, 0.0, 1.0]]", "[0.0, 1.0, 1.0]]"), "matrix"),
        (("-0.12, 0.05, 0.0, 0.0, 0.0", "-0.12, 0.05"), "distortion"),
        (("[camera]", "[lens]"), "no [camera] table"),
    ],
)
def test_bad_camera_toml_names_the_key(tmp_path, edit, where):
    (tmp_path / "camera.toml").write_text(SPEC_CAMERA.replace(*edit, 1))
    with pytest.raises(InputError) as info:
        load_intrinsics(tmp_path / "camera.toml")
    text = str(info.value) + " ".join(getattr(info.value, "problems", []) or [])
    assert where in text and "camera.toml" in text


def test_written_session_reads_back(small_session):
    s = load_session(small_session.directory)
    assert s.config.camera is not None and len(s.poses) == 3
    intr = load_intrinsics(small_session.directory / "camera.toml")
    np.testing.assert_allclose(intr.vector, true_intrinsics(small_session.rig).vector)
    frames = list(read_frames(s.take_path(0), intr.image_size))
    assert [f.name for f in frames] == ["frame_1.jpg", "frame_2.jpg"]
    assert frames[0].image.shape == (360, 640, 3)


def test_frames_in_natural_order_any_case(tmp_path):
    img = np.zeros((4, 6, 3), np.uint8)
    for name in ("frame_10.JPG", "frame_2.png", "frame_1.jpeg", "notes.txt", ".hidden.png"):
        (tmp_path / name).write_bytes(
            cv2.imencode(".png", img)[1].tobytes() if not name.endswith("txt") else b"x"
        )
    assert [p.name for p in image_files(tmp_path)] == [
        "frame_1.jpeg",
        "frame_2.png",
        "frame_10.JPG",
    ]
    assert natural_key("a2") < natural_key("a10")


def test_picture_of_another_size_is_refused_naming_it(small_session, tmp_path):
    take = tmp_path / "take"
    shutil.copytree(load_session(small_session.directory).take_path(1), take)
    cv2.imwrite(str(take / "frame_3.png"), np.zeros((100, 200, 3), np.uint8))
    with pytest.raises(InputError) as info:
        list(read_frames(take, (640, 360)))
    assert "frame_3.png" in str(info.value) and "200x100" in str(info.value)


def test_empty_or_missing_take_is_refused(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no pictures"):
        list(read_frames(tmp_path / "empty"))
    with pytest.raises(InputError, match="no such take"):
        list(read_frames(tmp_path / "nothing"))
    (tmp_path / "bad.avi").write_bytes(b"not a video")
    with pytest.raises(InputError, match="video"):
        list(read_frames(tmp_path / "bad.avi"))


def test_video_takes(tmp_path, sim_model):
    s = write_camera_session(
        tmp_path / "v",
        sim_model,
        sim_model,
        np.array([[0.0, 0.0, 220.0]]),
        rig=rig_for_size((640, 360)),
        intrinsics="truth",
        take_kind="video",
        frames_per_take=3,
        supersample=1,
    )
    session = load_session(s.directory)
    assert session.poses.take[0].endswith(".avi")
    frames = list(read_frames(session.take_path(0), (640, 360)))
    assert [f.name for f in frames] == ["frame 1", "frame 2", "frame 3"]


def test_session_toml_round_trip(tmp_path):
    from cdprhost.calibration.session import SessionConfig
    from cdprhost.calibration.session_writer import session_toml
    from cdprhost.sim.camera.session import camera_config

    cam = camera_config(rig_for_size((640, 360)), "views", max_spread_mm=0.5, accuracy_mm=0.2)
    cfg = SessionConfig.model_validate({"session": {"profile": "p"}, "camera": cam})
    (tmp_path / "session.toml").write_text(session_toml(cfg))
    back = load_session_config(tmp_path / "session.toml")
    assert back.model_dump() == cfg.model_dump()
    assert back.declared_noise_mm == 0.2 and back.acceptance.max_spread_mm == 0.5
