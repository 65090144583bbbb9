"""The simulated camera renders what the geometry says: OpenCV finds the corners where the
lens model projects them, a near board hides the one behind it, views cover the image."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.calibration.camera.detection import detect_board
from cdprhost.sim.camera.imaging import Imaging, decode
from cdprhost.sim.camera.optics import PinholeCamera, distort, undistort
from cdprhost.sim.camera.scene import CALIBRATION_BOARD, rig_for_size, standard_rig
from cdprhost.sim.camera.views import render_views, tilt_of, view_poses

STRONG = np.array([-0.3, 0.12, 0.001, -0.001, -0.02])


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-0.6, 0.6),
    y=st.floats(-0.4, 0.4),
    k1=st.floats(-0.3, 0.1),
    k2=st.floats(-0.1, 0.15),
)
def test_undistort_inverts_distort(x, y, k1, k2):
    dist = np.array([k1, k2, 0.0005, -0.0003, 0.0])
    xy = np.array([[x, y]])
    back = undistort(distort(xy, dist), dist)
    if np.isfinite(back).all():  # where the lens model folds over, NaN is the honest answer
        np.testing.assert_allclose(back, xy, atol=1e-9)
    else:
        assert x * x + y * y > 0.3


def test_projection_matches_opencv():
    cam = PinholeCamera.from_fov((800, 600), 60.0, STRONG).placed((100, -500, 400), (0, 0, 150))
    pts = np.random.default_rng(0).uniform([-100, -100, 0], [100, 100, 300], (50, 3))
    rvec, _ = cv2.Rodrigues(cam.rotation)
    ref, _ = cv2.projectPoints(pts, rvec, cam.translation, cam.matrix, cam.distortion)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-6)


def _detect(gray, board):
    d = detect_board(gray, board)
    return (np.zeros((0, 2)), np.zeros(0, int)) if d is None else (d.corners_px, d.ids)


@pytest.fixture(scope="module")
def small_rig():
    return rig_for_size((960, 540))


def test_corners_found_where_the_lens_model_puts_them(small_rig):
    rig = small_rig
    renderer = rig.renderer()
    b = np.array([10.0, -20.0, 200.0])
    gray = cv2.cvtColor(
        decode(rig.frame(renderer, b, np.random.default_rng(1))), cv2.COLOR_BGR2GRAY
    )
    for placed in rig.boards(b):
        corners, ids = _detect(gray, placed.layout)
        assert len(ids) >= 0.8 * len(placed.layout.corners_mm), placed.layout
        truth = rig.camera.project(
            placed.origin + placed.layout.corners_mm[ids] @ placed.rotation.T
        )
        err = corners - truth
        assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.2  # px, through noise and JPEG
        assert np.all(np.abs(err.mean(axis=0)) < 0.06)  # no bias


def test_a_near_board_hides_what_is_behind_it(small_rig):
    rig = small_rig
    renderer = rig.renderer()
    ref = rig.reference_board()
    centre = ref.outline().mean(axis=0)
    # put the effector board on the line from the camera to the reference board's centre
    toward = rig.camera.position + 0.6 * (centre - rig.camera.position)
    b = (
        toward
        + rig.effector_rotation @ np.array(rig.setup.effector.offset)
        - rig.effector_rotation @ np.array([60.0, 45.0, 0.0])
    )
    both = renderer.radiance(rig.boards(b))
    alone = renderer.radiance([ref])
    u, v = np.round(rig.camera.project(rig.effector_board(b).outline().mean(axis=0))).astype(int)
    patch = (slice(v - 3, v + 4), slice(u - 3, u + 4))
    assert not np.allclose(both[patch], alone[patch])
    assert not rig.visible(b[None])[0]  # the planner would not choose this pose


def test_blur_noise_and_light_degrade_the_picture(small_rig):
    rig = small_rig
    renderer = rig.renderer()
    b = np.array([0.0, 0.0, 220.0])
    rng = np.random.default_rng(0)

    def sharpness(imaging):
        r = rig.with_imaging(**imaging)
        g = cv2.cvtColor(decode(r.frame(renderer, b, rng)), cv2.COLOR_BGR2GRAY)
        return cv2.Laplacian(g, cv2.CV_64F).var()

    sharp = sharpness({})
    assert sharpness({"motion_px": 15.0}) < 0.5 * sharp
    assert sharpness({"defocus_px": 6.0}) < 0.5 * sharp
    dark = rig.with_imaging(light=0.05)
    g = decode(dark.frame(renderer, b, rng)).astype(float)
    g0 = decode(rig.frame(renderer, b, rng)).astype(float)
    assert np.std(g - g0) > 3 * np.std(decode(rig.frame(renderer, b, rng)).astype(float) - g0)


def test_png_is_lossless_and_jpeg_smaller(small_rig):
    renderer = small_rig.renderer()
    b = np.array([0.0, 0.0, 220.0])
    png = small_rig.with_imaging(jpeg_quality=None).frame(renderer, b, np.random.default_rng(0))
    jpg = small_rig.frame(renderer, b, np.random.default_rng(0))
    assert png[:4] == b"\x89PNG" and jpg[:2] == b"\xff\xd8"
    assert len(jpg) < len(png)


def test_calibration_views_cover_the_image_and_tilt():
    cam = standard_rig(image_size=(640, 480)).camera
    good = view_poses(cam, CALIBRATION_BOARD, 12, "good")
    poor = view_poses(cam, CALIBRATION_BOARD, 6, "poor")
    assert len(good) == 12 and len(poor) == 6
    centres = np.array([cam.project(p.outline()).mean(axis=0) for p in good])
    assert np.ptp(centres[:, 0]) > 0.4 * 640 and np.ptp(centres[:, 1]) > 0.3 * 480
    assert max(tilt_of(p) for p in good) > 25 and max(tilt_of(p) for p in poor) < 6
    pics = render_views(cam, Imaging(), CALIBRATION_BOARD, 2, supersample=1)
    assert decode(pics[0]).shape == (480, 640, 3)


def test_partial_occlusion_hides_some_corners(small_rig):
    from cdprhost.sim.camera.scene import occluder_over

    renderer = small_rig.renderer()
    b = np.array([0.0, 0.0, 220.0])
    ref = small_rig.reference_board()

    def corners(hide):
        img = decode(small_rig.frame(renderer, b, np.random.default_rng(0), hide))
        return len(_detect(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), ref.layout)[1])

    full = corners(())
    half = corners([occluder_over(small_rig, b, 0.45, "reference", side=0)])
    assert 0 < half < 0.75 * full
