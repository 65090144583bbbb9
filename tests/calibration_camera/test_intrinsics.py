"""Detection and intrinsics on rendered ChArUco views (small images: fast)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera import (
    CharucoBoard,
    Intrinsics,
    calibrate_intrinsics,
    detect_board,
    solve_board_pose,
)
from cdprhost.calibration.camera.projection import project
from tests.calibration_camera.render import render
from tests.calibration_camera.views import render_views, view_poses

SIZE = (960, 540)
TRUTH = Intrinsics(
    np.array([[690.0, 0.0, 483.0], [0.0, 690.7, 266.0], [0.0, 0.0, 1.0]]),
    np.array([-0.12, 0.05, 0.0, 0.0, 0.0]),
    SIZE,
)
CAL_BOARD = CharucoBoard((9, 6), 25.0, 18.0, "DICT_5X5_250", 150)
SMALL = CharucoBoard((5, 4), 16.0, 12.0, "DICT_5X5_250", 100)


@pytest.mark.parametrize(("blur", "noise", "jpeg"), [(0.0, 0.0, None), (0.8, 2.0, 90)])
def test_corners_are_found_to_a_tenth_of_a_pixel(blur, noise, jpeg):
    rng = np.random.default_rng(1)
    rot = Rotation.from_euler("xyz", [25, -15, 5], degrees=True).as_matrix()
    t = np.array([-60.0, 20.0, 350.0])
    img = render([(SMALL, rot, t)], TRUTH, blur_px=blur, noise=noise, jpeg=jpeg, rng=rng)
    d = detect_board(img, SMALL)
    assert d is not None and len(d) >= 10
    truth = project(SMALL.corners_mm[d.ids] @ rot.T + t, TRUTH.vector)
    assert np.sqrt(np.mean(np.sum((d.corners_px - truth) ** 2, axis=1))) < 0.1
    pose = solve_board_pose(d, SMALL, TRUTH)
    assert pose is not None and pose.rms_px < 0.3
    assert np.linalg.norm(pose.tvec - t) < 2.0
    # the depth is the least certain direction of the board's position
    w, v = np.linalg.eigh(pose.covariance[3:, 3:])
    assert abs(v[:, -1] @ (t / np.linalg.norm(t))) > 0.9


def test_a_board_that_is_not_there_or_drowned_in_blur_is_not_found():
    rot, t = np.eye(3), np.array([0.0, 0.0, 900.0])
    assert detect_board(render([], TRUTH), SMALL) is None
    img = render([(SMALL, rot, t)], TRUTH, blur_px=6.0, noise=4, rng=np.random.default_rng(0))
    assert detect_board(img, SMALL) is None


@pytest.fixture(scope="module")
def good_views():
    rng = np.random.default_rng(3)
    poses = view_poses(TRUTH, CAL_BOARD, rng, 12, distance_mm=600.0)
    return [
        detect_board(im, CAL_BOARD)
        for im in render_views(TRUTH, CAL_BOARD, poses, rng, blur_px=0.6, noise=2, jpeg=92)
    ]


def test_intrinsics_from_good_views(good_views):
    r = calibrate_intrinsics(good_views, CAL_BOARD, SIZE)
    assert r.ok, r.problems
    assert r.rms_px < 0.2
    v, t = r.intrinsics.vector, TRUTH.vector
    std = r.intrinsics.std
    assert np.all(std[:6] > 0) and std[8] == 0.0  # k3 held at 0
    # within a few reported standard deviations (and the reported std is small)
    assert abs(v[0] - t[0]) < max(4 * std[0], 0.002 * t[0])
    assert std[0] / t[0] < 0.005
    assert abs(v[4] - t[4]) < 0.02


def test_face_on_views_are_refused_with_what_to_add():
    rng = np.random.default_rng(4)
    poses = view_poses(TRUTH, CAL_BOARD, rng, 10, distance_mm=600.0, max_tilt_deg=3.0)
    dets = [detect_board(im, CAL_BOARD) for im in render_views(TRUTH, CAL_BOARD, poses, rng)]
    r = calibrate_intrinsics(dets, CAL_BOARD, SIZE)
    assert not r.ok
    assert "tilted" in r.coverage.reason and "tilted 20-45 deg" in r.coverage.advice


def test_clustered_views_are_refused_where_the_boards_are_seen():
    rng = np.random.default_rng(6)
    poses = view_poses(TRUTH, CAL_BOARD, rng, 10, distance_mm=700.0, spread=0.1)
    dets = [detect_board(im, CAL_BOARD) for im in render_views(TRUTH, CAL_BOARD, poses, rng)]
    r = calibrate_intrinsics(dets, CAL_BOARD, SIZE)
    assert r.coverage.cell_fraction < 0.75
    # the machine's boards seen all over the picture: the lens is not known there
    w, h = SIZE
    everywhere = np.stack(np.meshgrid(np.linspace(5, w - 5, 12), np.linspace(5, h - 5, 8)), -1)
    judged = r.judged_for(everywhere.reshape(-1, 2), "all over")
    assert not judged.ok
    assert "where the machine's boards are seen (all over" in judged.coverage.reason
    advice = judged.coverage.advice
    assert advice.startswith("add views with the board near ")
    assert any(c in advice for c in ("top-left", "top-right", "bottom-left", "bottom-right"))


def test_too_few_views_raise_naming_them():
    with pytest.raises(ValueError, match="usable calibration view"):
        calibrate_intrinsics([None, None], CAL_BOARD, SIZE)
