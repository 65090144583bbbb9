"""Kabsch fit: random rigid transforms, gaps and weights, batches, and the paper's section 6.2 frame."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.calibration.mocap.readers import Take
from cdprhost.calibration.mocap.registration import (
    is_degenerate,
    kabsch,
    register_frames,
    rotation_about_z,
)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(3, 12),
    planar=st.booleans(),
    scale=st.floats(1.0, 2000.0),
)
def test_kabsch_recovers_random_rigid_transforms(seed, n, planar, scale):
    rng = np.random.default_rng(seed)
    src = rng.uniform(-scale, scale, (n, 3))
    if planar:  # base markers are usually coplanar: the reflection case must still give a rotation
        src[:, 2] = 0.0
    if is_degenerate(src):
        return
    rot, t = random_rotation(rng), rng.uniform(-3000, 3000, 3)
    fit = kabsch(src, src @ rot.T + t)
    np.testing.assert_allclose(fit.R, rot, atol=1e-8)
    np.testing.assert_allclose(fit.t, t, atol=1e-7 * max(scale, 3000.0))
    assert np.linalg.det(fit.R) == pytest.approx(1.0)
    assert fit.rms_residual < 1e-8 * scale and fit.n_points == n
    np.testing.assert_allclose(fit.inverse().apply(fit.apply(src)), src, atol=1e-8 * scale)


@given(seed=st.integers(0, 2**32 - 1))
def test_kabsch_batch_equals_per_frame_and_gaps_drop_out(seed):
    rng = np.random.default_rng(seed)
    spread = np.array(
        [(0, 300, 0), (-260, -150, 0), (260, -150, 0), (0, 0, 200), (100, 50, -150)], dtype=float
    )
    nominal = spread + rng.uniform(-30, 30, (5, 3))
    rots = np.array([random_rotation(rng) for _ in range(6)])
    ts = rng.uniform(-1000, 1000, (6, 3))
    measured = np.einsum("fij,nj->fni", rots, nominal) + ts[:, None] + rng.normal(0, 0.1, (6, 5, 3))
    measured[2, 1] = np.nan  # a gap: that frame fits on the other four markers
    measured[4, 0] = [1e4, 1e4, 1e4]  # a wild point, given weight 0 below
    weights = np.ones((6, 5))
    weights[4, 0] = 0.0
    batch = kabsch(measured, nominal[None], weights)
    for f in range(6):
        keep = np.isfinite(measured[f]).all(axis=1) & (weights[f] > 0)
        one = kabsch(measured[f][keep], nominal[keep])
        np.testing.assert_allclose(batch.R[f], one.R, atol=1e-10)
        np.testing.assert_allclose(batch.t[f], one.t, atol=1e-7)
        assert batch.rms_residual[f] == pytest.approx(float(one.rms_residual), rel=1e-9)
        np.testing.assert_allclose(
            batch.R[f], rots[f].T, atol=2e-3
        )  # mocap -> nominal undoes the pose
    assert list(batch.n_points) == [5, 5, 4, 5, 4, 5]


def test_kabsch_marks_impossible_fits_invalid():
    line = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 0, 0]])
    assert not kabsch(line, line + 1.0).valid
    two = np.array([[0.0, 0, 0], [1, 2, 3], [np.nan, 0, 0]])
    fit = kabsch(two, two)
    assert not fit.valid and np.isnan(fit.R).all() and fit.n_points == 2
    assert is_degenerate(line) and not is_degenerate(np.eye(3))


def test_register_frames_maps_a_take_into_the_base_frame():
    nominal = {"F1": (0.0, 300.0, 0.0), "F2": (-259.8, -150.0, 0.0), "F3": (259.8, -150.0, 0.0)}
    rot = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]) @ rotation_about_z(
        0.7
    )  # Motive Y-up world
    t = np.array([900.0, 15.0, -400.0])
    base = np.array(list(nominal.values()))
    effector = np.array([[10.0, 20.0, 150.0]])
    world = np.vstack([base, effector]) @ rot.T + t
    take = Take(
        ("F1", "F2", "F3", "E"),
        np.repeat(world[None], 4, axis=0),
        np.arange(4) / 100,
        "s",
        "motive-csv",
    )
    reg = register_frames(take, nominal)
    assert reg.R.shape == (4, 3, 3) and reg.valid.all()
    np.testing.assert_allclose(
        reg.apply(take.select(["E"])), np.broadcast_to(effector, (4, 1, 3)), atol=1e-9
    )


# --- Paper, section 6.2 (Table 5 and eq. 24) -------------------------------------------------
TABLE5 = np.array(
    [(547.7330, 160.4733, 24.0144), (362.9547, -147.6336, 22.0150), (716.6375, -158.7557, 23.4959)]
)
PRINTED_ORIGIN = np.array([542.4536, 48.4085, 23.1651])
EQ24 = np.array(
    [[0.483768011, 0.875196271, 0.0], [-0.875196271, 0.483768011, 0.0], [0.0, 0.0, 1.0]]
)  # B in A


def test_paper_origin_is_the_marker_centroid_with_y_sign_corrected():
    centroid = TABLE5.mean(axis=0)
    np.testing.assert_allclose(centroid, [542.4417, -48.6387, 23.1751], atol=1e-4)
    corrected = PRINTED_ORIGIN * [1, -1, 1]
    assert np.linalg.norm(centroid - corrected) < 0.25  # as printed, but y negative
    assert abs(centroid[1] - PRINTED_ORIGIN[1]) > 95.0  # the printed sign is impossible


def test_paper_rotation_is_the_y_axis_from_F2_to_the_origin():
    """Eq. 24's y axis (its 2nd column) is the unit vector from F2 to the origin: F2 lies on -y."""
    origin = PRINTED_ORIGIN * [1, -1, 1]
    y = (origin - TABLE5[1])[:2]
    y /= np.linalg.norm(y)
    np.testing.assert_allclose(EQ24[:2, 1], y, atol=1e-4)
    np.testing.assert_allclose(
        EQ24[:2, 0], [y[1], -y[0]], atol=1e-4
    )  # x = y turned -90 deg about z


def test_kabsch_reproduces_eq24_from_the_surveyed_base_positions():
    """Nominal positions: the markers as the paper's frame B sees them, rounded to 0.01 mm.

    F2 on the -y axis, F1 upper left, F3 upper right (and their small height
    differences); the fit of the measured markers to them returns eq. 24, and
    ``p_B = R^-1 (p_A - p_B0)`` is our transform (R = eq24^T, t = -eq24^T p_B0).
    """
    nominal = np.array([(-180.26, 105.67, 0.85), (0.01, -205.10, -1.15), (180.84, 99.06, 0.33)])
    fit = kabsch(TABLE5, nominal)  # mocap (A) -> base (B)
    r_b_in_a = fit.R.T
    assert r_b_in_a[0, 0] == pytest.approx(0.483768, abs=1e-4) and r_b_in_a[1, 0] == pytest.approx(
        -0.875196, abs=1e-4
    )
    np.testing.assert_allclose(r_b_in_a, EQ24, atol=1e-4)
    origin_in_a = fit.inverse().t
    np.testing.assert_allclose(origin_in_a, PRINTED_ORIGIN * [1, -1, 1], atol=0.02)
    assert fit.rms_residual < 0.01


def test_equilateral_nominal_base_shows_why_the_surveyed_positions_matter():
    """The measured triangle is not equilateral (sides 353.9 to 361.2 mm): fitting it to an
    ideal one with F2 on -y still lands within 0.6 deg of eq. 24 but leaves a 2.5 mm RMS misfit,
    which the 0.5 mm take check rejects. Any other assignment is 60+ deg off."""
    c = np.sqrt(3.0) / 2.0
    r = np.linalg.norm(TABLE5 - TABLE5.mean(axis=0), axis=1).mean()
    ideal = r * np.array([(-c, 0.5, 0.0), (0.0, -1.0, 0.0), (c, 0.5, 0.0)])
    fit = kabsch(TABLE5, ideal)
    yaw = np.degrees(np.arctan2(fit.R.T[1, 0], fit.R.T[0, 0]))
    assert yaw == pytest.approx(np.degrees(np.arctan2(-0.875196, 0.483768)), abs=0.6)
    assert 2.0 < fit.rms_residual < 3.0
    f1_on_y = r * np.array([(0.0, 1.0, 0.0), (-c, -0.5, 0.0), (c, -0.5, 0.0)])
    other = kabsch(TABLE5, f1_on_y).R.T
    assert abs(np.degrees(np.arctan2(other[1, 0], other[0, 0])) - yaw) > 55.0
