import numpy as np

from cdprhost.kinematics.workspace import RULES, triangle_excess


def test_triangle_membership():
    side = 170.0
    r = side / np.sqrt(3)
    inside = np.array([[0, 0], [0, r * 0.99], [-side / 2 * 0.99, -r / 2 * 0.99]])
    outside = np.array([[0, r * 1.01], [0, -r / 2 - 1], [side / 2 + 1, -r / 2]])
    assert (triangle_excess(inside, side) <= 0).all()
    assert (triangle_excess(outside, side) > 0).all()
    np.testing.assert_allclose(triangle_excess(np.array([[0.0, -r / 2 - 1]]), side), 1.0)


def test_each_rule_is_named(sim_model):
    pts = np.array([[0, 0, 200.0], [0, 0, 100.0], [0, 0, 345.0], [80, 60, 200.0]])
    rep = sim_model.check(pts)
    names = [rep.rule_name(i) for i in range(len(pts))]
    assert names[0] is None
    assert names[1] == "build_volume"
    assert names[2] in RULES and rep.excess[2] > 0
    assert names[3] is not None
    for i in range(1, 4):
        assert rep.describe(i, sim_model.limits)


def test_slider_travel_rule(sim_model):
    # far above the initial pose the sliders pay out more than +40 mm
    rep = sim_model.check(np.array([[0.0, 0.0, 400.0]]))
    assert rep.rule_name(0) in ("slider_travel", "tension")
    s = sim_model.ik(np.array([[0.0, 0.0, 200.0]]))
    s[0, 1] = 41.0
    rep = sim_model.check(np.array([[0.0, 0.0, 200.0]]), s)
    assert rep.rule_name(0) == "slider_travel" and int(rep.cable[0]) == 1
    np.testing.assert_allclose(rep.excess[0], 1.0)


def test_tension_rule_under_high_acceleration(sim_profile):
    from cdprhost.kinematics import MachineModel

    data = sim_profile.model_dump()
    data["statics"]["a_max_mm_s2"] = 200000.0
    from cdprhost.profile import profile_from_dict

    model = MachineModel.from_profile(profile_from_dict(data))
    rep = model.check(np.array([[0.0, 0.0, 300.0]]))
    assert rep.rule_name(0) == "tension"
