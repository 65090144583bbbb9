import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.effects import CATALOGUE, EffectChain, MotionContext
from cdprhost.effects.backlash import path_directions
from cdprhost.kinematics import MachineModel, tensions
from cdprhost.kinematics.geometry import cable_lengths
from cdprhost.profile import profile_from_dict
from tests.kinematics.strategies import point_clouds

ALL_EFFECTS = {
    "cable_elasticity": {"EA": 20000.0},
    "drive_scale": {"eps": [0.004, -0.006, 0.003]},
    "backlash": {"beta": [0.2, 0.15, 0.3]},
    "drift": {"rho": [3e-4, -2e-4, 4e-4]},
}


def model_with(sim_profile, effects):
    data = sim_profile.model_dump()
    data["effects"] = effects
    return MachineModel.from_profile(profile_from_dict(data))


@given(point_clouds(32), st.floats(0, 3600), st.sampled_from([-1.0, 1.0]))
def test_prediction_inverts_compensation_with_every_effect(sim_profile, points, t, d):
    model = model_with(sim_profile, ALL_EFFECTS)
    ctx = MotionContext(t_s=np.full(len(points), t), directions=np.full((len(points), 3), d))
    s_cmd = model.ik(points, ctx)
    assert np.abs(model.fk(s_cmd, ctx) - points).max() < 1e-9
    assert np.abs(model.length_residuals(points, s_cmd, ctx)).max() < 1e-9


def test_spec_equations_for_each_effect(sim_profile):
    p = np.array([[10.0, -20.0, 180.0]])
    ideal = MachineModel.from_profile(sim_profile)
    s = ideal.ik(p)
    ctx = MotionContext(t_s=np.array([100.0]), directions=np.array([[1.0, -1.0, 1.0]]))
    scale = model_with(sim_profile, {"drive_scale": ALL_EFFECTS["drive_scale"]})
    np.testing.assert_allclose(scale.ik(p), s / (1 + np.array([0.004, -0.006, 0.003])))
    lash = model_with(sim_profile, {"backlash": ALL_EFFECTS["backlash"]})
    np.testing.assert_allclose(lash.ik(p, ctx), s + np.array([0.2, 0.15, 0.3]) * [1, -1, 1])
    drift = model_with(sim_profile, {"drift": ALL_EFFECTS["drift"]})
    np.testing.assert_allclose(drift.ik(p), s)  # no compensation while printing
    np.testing.assert_allclose(
        drift.fk(s, ctx), ideal.fk(s + np.array([3e-4, -2e-4, 4e-4]) * 100.0)
    )
    ela = model_with(sim_profile, {"cable_elasticity": {"EA": 20000.0}})
    t = tensions(p, ideal.geometry.outlets, ideal.statics)
    expected = (
        cable_lengths(p, ideal.geometry.outlets) / (1 + t / 20000.0)
        - ideal.geometry.initial_lengths
    )
    np.testing.assert_allclose(ela.ik(p), expected)


def test_path_directions_carry_last_motion():
    s = np.array([[0, 0, 0], [1, 0, -1], [1, 0, -2], [0.5, 1, -2], [0.5, 1, -2.0]])
    d = path_directions(s)
    np.testing.assert_array_equal(d[:, 0], [1, 1, 1, -1, -1])
    np.testing.assert_array_equal(d[:, 1], [1, 1, 1, 1, 1])
    np.testing.assert_array_equal(d[:, 2], [-1, -1, -1, -1, -1])


def test_effect_tables_round_trip():
    chain = EffectChain.from_tables(ALL_EFFECTS)
    again = EffectChain.from_tables(chain.to_tables())
    for a, b in zip(chain.vectors, again.vectors):
        np.testing.assert_allclose(a, b)
    assert set(chain.names) == set(CATALOGUE)


def test_bad_effect_tables_are_named(sim_profile):
    from cdprhost.errors import InputError

    data = sim_profile.model_dump()
    data["effects"] = {"cable_elasticity": {"EA": -5.0}, "warp_drive": {}}
    with pytest.raises(InputError) as err:
        profile_from_dict(data)
    text = str(err.value)
    assert "effects.cable_elasticity.EA" in text and "effects.warp_drive" in text
