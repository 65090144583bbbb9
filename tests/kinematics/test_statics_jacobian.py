import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.kinematics import identification_jacobian, tensions, velocity_jacobian
from cdprhost.kinematics.geometry import CableGeometry, fk_points, ik_sliders
from cdprhost.kinematics.statics import cable_units
from tests.kinematics.strategies import build_points, point_clouds

accels = st.lists(st.floats(-2000, 2000), min_size=3, max_size=3)


@given(point_clouds(16), accels)
def test_tensions_satisfy_force_balance(sim_model, points, a):
    sp = sim_model.statics
    acc = np.tile(np.array(a), (len(points), 1))
    t = tensions(points, sim_model.geometry.outlets, sp, acc)
    u = cable_units(points, sim_model.geometry.outlets)
    spring = sp.f0 + sp.k_s * (sp.z_ref - points[:, 2])
    total = np.einsum("nk,nkj->nj", t, u)
    total[:, 2] += spring - sp.mass * sp.gravity
    total += sp.external
    np.testing.assert_allclose(total, sp.mass * 1e-3 * acc, atol=1e-9)


def test_tensions_positive_at_rest_inside_build_volume(sim_model):
    pts = np.array([[0, 0, 110.0], [0, 0, 330.0], [40, -20, 200.0]])
    assert (tensions(pts, sim_model.geometry.outlets, sim_model.statics) > 0).all()


@given(build_points())
def test_velocity_jacobian_matches_finite_differences(sim_model, p):
    g = sim_model.geometry
    jac = velocity_jacobian(p[None], g.outlets)[0]
    h = 1e-6
    fd = np.stack(
        [
            (ik_sliders((p + h * e)[None], g) - ik_sliders((p - h * e)[None], g))[0] / (2 * h)
            for e in np.eye(3)
        ],
        axis=1,
    )
    np.testing.assert_allclose(jac, fd, atol=1e-7)


@given(build_points(z_min=110, z_max=300))
def test_identification_jacobian_matches_finite_differences(sim_model, p):
    """dB = J0 dq at fixed slider displacements (paper eq. 4-6)."""
    g = sim_model.geometry
    s = ik_sliders(p[None], g)
    j0 = identification_jacobian(p[None], g)
    h = 1e-6
    fd = np.empty((3, 12))
    for i in range(12):
        dq = np.zeros(12)
        dq[i] = h
        plus = fk_points(s, CableGeometry.from_q(g.q + dq))[0]
        minus = fk_points(s, CableGeometry.from_q(g.q - dq))[0]
        fd[:, i] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(j0, fd, atol=1e-6)


def test_coplanar_poses_leave_outlet_heights_poorly_observed(sim_model):
    """The paper's Table 1 poses (one plane, close together) give a near-singular J0."""
    table1 = np.array(
        [
            [-30.231, 24.537, 110],
            [-42.5, 24.537, 110],
            [-31.832, 43.015, 110],
            [-36.366, 13.912, 110],
        ]
    )
    sv = np.linalg.svd(identification_jacobian(table1, sim_model.geometry), compute_uv=False)
    spread = np.random.default_rng(1).uniform([-50, -40, 120], [50, 40, 320], (12, 3))
    sv_spread = np.linalg.svd(identification_jacobian(spread, sim_model.geometry), compute_uv=False)
    assert sv[-1] / sv[0] < sv_spread[-1] / sv_spread[0]
