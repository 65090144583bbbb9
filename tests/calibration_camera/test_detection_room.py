"""Detection in a real room: a false marker whose id collides with the board's must not
cost the view; a board that is not found says what was decoded and which layout fits."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera import CharucoBoard, Intrinsics, detect_board
from cdprhost.calibration.camera.detection import explain_missing_board, markers_on_board
from tests.calibration_camera.render import render

SIZE = (960, 540)
TRUTH = Intrinsics(
    np.array([[690.0, 0.0, 483.0], [0.0, 690.7, 266.0], [0.0, 0.0, 1.0]]),
    np.array([-0.12, 0.05, 0.0, 0.0, 0.0]),
    SIZE,
)
BOARD = CharucoBoard((7, 5), 25.0, 18.0, "DICT_5X5_250", 0)


def _view(board: CharucoBoard = BOARD, seed: int = 0) -> np.ndarray:
    rot = Rotation.from_euler("xyz", [20, -15, 4], degrees=True).as_matrix()
    t = np.array([-40.0, -30.0, 420.0])
    return render([(board, rot, t)], TRUTH, blur_px=0.5, noise=1.5, rng=np.random.default_rng(seed))


def _paste_marker(img: np.ndarray, marker_id: int, at: tuple[int, int], side: int) -> None:
    """A marker of the board's dictionary printed somewhere else in the room (white rim)."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_250)
    m = cv2.aruco.generateImageMarker(d, marker_id, side)
    rim = side // 4
    m = cv2.copyMakeBorder(m, rim, rim, rim, rim, cv2.BORDER_CONSTANT, value=255)
    x, y = at
    img[y : y + m.shape[0], x : x + m.shape[1]] = m


def test_a_false_marker_sharing_a_board_id_does_not_cost_the_view():
    clean = detect_board(_view(), BOARD)
    assert clean is not None and len(clean) >= 20
    img = _view()
    _paste_marker(img, 3, (860, 420), 36)  # id 3 is on the board too
    _paste_marker(img, 12, (20, 440), 30)
    d = detect_board(img, BOARD)
    assert d is not None, "the view was lost to the impostors"
    assert set(d.ids.tolist()) >= set(clean.ids.tolist()) - {0}
    common = np.intersect1d(d.ids, clean.ids)
    a = d.corners_px[np.searchsorted(d.ids, common)]
    b = clean.corners_px[np.searchsorted(clean.ids, common)]
    assert np.max(np.linalg.norm(a - b, axis=1)) < 0.05


def test_impostor_markers_are_told_from_the_board_by_its_layout():
    objs = np.asarray(BOARD.cv_board.getObjPoints(), float)
    hom = np.array([[2.0, 0.2, 300.0], [-0.1, 2.1, 100.0], [1e-4, 2e-4, 1.0]])

    def image_of(o: np.ndarray) -> np.ndarray:
        q = np.c_[o[:, :2], np.ones(4)] @ hom.T
        return q[:, :2] / q[:, 2:]

    ids = np.arange(8)
    quads = np.array([image_of(objs[i]) for i in ids])
    fake = quads[3] + np.array([400.0, 250.0])  # id 3 again, far from where the board puts it
    lost = quads[5] + np.array([-35.0, 0.0])  # id 5 alone, a marker away from its place
    keep = markers_on_board(
        np.concatenate([quads[[0, 1, 2, 3, 4, 6, 7]], [fake, lost]]),
        np.array([0, 1, 2, 3, 4, 6, 7, 3, 5]),
        BOARD,
    )
    assert keep.tolist() == [True] * 7 + [False, False]


def test_a_legacy_or_transposed_board_is_not_found_with_a_hint():
    legacy = CharucoBoard((6, 4), 25.0, 18.0, "DICT_5X5_250", 0, legacy_pattern=True)
    img = _view(legacy)
    modern = CharucoBoard((6, 4), 25.0, 18.0, "DICT_5X5_250", 0)
    assert detect_board(img, modern) is None or len(detect_board(img, modern)) < 6
    why = explain_missing_board(img, modern)
    assert "12 DICT_5X5_250 marker(s) decoded" in why and "legacy layout" in why, why
    assert detect_board(img, legacy) is not None
    swapped = CharucoBoard((5, 7), 25.0, 18.0, "DICT_5X5_250", 0)
    why = explain_missing_board(_view(), swapped)
    assert "7x5 board (the sizes swapped)" in why, why
    assert "no DICT_5X5_250 marker decoded" in explain_missing_board(
        np.full((540, 960), 120, np.uint8), BOARD
    )


def test_the_legacy_layout_can_be_said_in_the_compact_board_spec():
    from cdprhost.cli.camera_calibration import parse_board

    board = parse_board("6x4,25,18,DICT_5X5_250,0,legacy")
    assert board.legacy_pattern and board.squares == (6, 4)
    assert parse_board("6x4,25,18, LEGACY").legacy_pattern
    assert not parse_board("6x4,25,18").legacy_pattern
    d = detect_board(_view(CharucoBoard((6, 4), 25.0, 18.0, legacy_pattern=True)), board)
    assert d is not None and len(d) == 15
