import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.kinematics import CableGeometry, cable_lengths, fk_points, ik_sliders
from tests.conftest import PAPER_TRUTH_OUTLETS
from tests.kinematics.strategies import build_points, point_clouds


def truth_geometry() -> CableGeometry:
    l0 = cable_lengths(np.array([[0.0, 0.0, 330.0]]), PAPER_TRUTH_OUTLETS)[0]
    return CableGeometry(PAPER_TRUTH_OUTLETS, l0)


def test_paper_truth_lengths_at_initial_pose():
    lengths = cable_lengths(np.array([[0.0, 0.0, 330.0]]), PAPER_TRUTH_OUTLETS)[0]
    np.testing.assert_allclose(lengths, 391.97, atol=0.01)
    assert np.allclose(ik_sliders(np.array([[0.0, 0.0, 330.0]]), truth_geometry()), 0.0, atol=1e-12)


def test_ik_matches_spec_formula_by_hand(sim_model):
    p = np.array([12.5, -7.25, 200.0])
    a = np.array(sim_model.geometry.outlets)
    expected = np.sqrt(((p - a) ** 2).sum(axis=1)) - sim_model.geometry.initial_lengths
    np.testing.assert_allclose(sim_model.ik(p[None])[0], expected, atol=1e-12)


@given(point_clouds())
def test_fk_inverts_ik(points):
    for geometry in (truth_geometry(),):
        back = fk_points(ik_sliders(points, geometry), geometry)
        assert np.abs(back - points).max() < 1e-9


@given(point_clouds())
def test_fk_inverts_ik_on_shipped_profiles(sim_model, proto_profile, points):
    from cdprhost.kinematics import MachineModel

    for model in (sim_model, MachineModel.from_profile(proto_profile)):
        assert np.abs(model.fk(model.ik(points)) - points).max() < 1e-9


@given(build_points(z_min=120.0), st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))
def test_ik_inverts_fk(p, ds):
    geometry = truth_geometry()
    s = ik_sliders(p[None], geometry)[0] + np.array(ds)
    again = ik_sliders(fk_points(s[None], geometry), geometry)[0]
    assert np.abs(again - s).max() < 1e-9


def test_fk_root_is_above_outlets():
    geometry = truth_geometry()
    p = fk_points(np.zeros((1, 3)), geometry)[0]
    np.testing.assert_allclose(p, [0.0, 0.0, 330.0], atol=1e-9)


def test_fk_unreachable_lengths_are_nan():
    geometry = truth_geometry()
    out = fk_points(np.array([[-380.0, -380.0, -380.0]]), geometry)
    assert np.isnan(out).all()


def test_steps_are_rounded_slider_times_steps_per_mm(sim_model):
    s = np.array([[0.00124, -0.00126, 10.0]])
    np.testing.assert_array_equal(sim_model.steps(s), [[0, -1, 4000]])
