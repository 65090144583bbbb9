import json
import tomllib

import numpy as np
import pytest

from cdprhost.diagnosis.augment import augmented_profile
from cdprhost.diagnosis.report import to_json, to_text
from cdprhost.diagnosis.workflow import FAST, diagnose
from cdprhost.effects.registry import EffectChain
from cdprhost.errors import InputError
from cdprhost.kinematics import MachineModel
from cdprhost.profile import profile_from_dict, profile_to_toml
from cdprhost.sim.measurement import simulate_observations
from cdprhost.sim.scenarios import hidden_truth, measurement_tour

CONTRACT_FIELDS = {
    "verdict",
    "effect",
    "candidates",
    "heldout_rms_before_mm",
    "heldout_rms_after_mm",
    "noise_floor_mm",
    "parameters",
    "where",
}


@pytest.fixture(scope="module")
def drift_diagnosis(make_session, sim_model):
    truth, _, obs = make_session("drift", 21, vector=np.array([3e-4, -4e-4, 2.5e-4]))
    return truth, obs, diagnose(obs, sim_model, settings=FAST)


def test_named_effect_parameters_and_intervals(drift_diagnosis):
    truth, _, d = drift_diagnosis
    assert d.verdict == "named" and d.effect == "drift"
    p = d.parameters["drift"]
    rho = np.array(p["vector"])
    np.testing.assert_allclose(rho, truth.effects.vectors[0], atol=4 * max(p["stderr"]))
    for (lo, hi), v in zip(p["ci95"]["rho"], rho):
        assert lo < v < hi
    assert p["table"]["rho"] == pytest.approx(list(rho)) and len(p["table"]["rho_stderr"]) == 3
    assert "time" in d.where and "explained by drift" in d.where


def test_json_report_has_the_contract_fields(drift_diagnosis):
    _, _, d = drift_diagnosis
    out = json.loads(json.dumps(to_json(d, session="s")))  # strict JSON round trip
    assert set(out) >= CONTRACT_FIELDS
    assert out["verdict"] == "named" and out["effect"] == "drift"
    names = [c["name"] for c in out["candidates"]]
    assert sorted(names) == sorted(["cable_elasticity", "drive_scale", "backlash", "drift"])
    for c in out["candidates"]:
        assert {"name", "p_value", "delta_bic", "heldout_rms_mm"} <= set(c)
    drift = next(c for c in out["candidates"] if c["name"] == "drift")
    assert drift["p_value"] < 1e-10 and drift["delta_bic"] < -100
    assert out["heldout_rms_after_mm"] < out["heldout_rms_before_mm"]
    assert out["noise_floor_mm"] == pytest.approx(d.noise_floor_mm)
    assert len(out["poses"]["heldout_before_mm"]) == 40
    assert any("re-home" in a for a in out["advice"])


def test_text_report_has_tables(drift_diagnosis):
    _, _, d = drift_diagnosis
    text = to_text(d, session="sess")
    assert "verdict: named: drift" in text
    assert "round 1: candidates against geometry" in text and "round 2" in text
    assert "drift.rho_1" in text and "95 % interval" in text


def test_augmented_profile_round_trips_and_carries_the_effect(drift_diagnosis, sim_profile):
    _, _, d = drift_diagnosis
    prof = augmented_profile(sim_profile, d, session="sess")
    again = profile_from_dict(tomllib.loads(profile_to_toml(prof)))
    assert set(again.effects) == {"drift"}
    assert again.calibration["diagnosis"]["verdict"] == "named"
    np.testing.assert_allclose(again.geometry.initial_lengths, d.final.fit.x_[9:12])
    model = MachineModel.from_profile(again)
    assert model.effects.names == ("drift",)


def test_two_hidden_effects_are_both_named(sim_model):
    rng = np.random.default_rng(5)
    truth = hidden_truth(sim_model, rng, None)
    chain = EffectChain.from_vectors(
        ["backlash", "drift"], [np.array([0.2, 0.25, 0.15]), np.array([3e-4, -3e-4, 4e-4])]
    )
    truth = truth.with_geometry(truth.geometry, chain)
    poses = measurement_tour(sim_model, 40, rng)
    obs = simulate_observations(
        truth, sim_model, poses, rng=rng, t_s=np.cumsum(rng.uniform(20, 60, 40))
    )
    d = diagnose(obs, sim_model, settings=FAST)
    assert d.verdict == "named" and set(d.effects) == {"backlash", "drift"}
    assert len(d.rounds) >= 2 and d.final.heldout_rms_mm < 1.3 * d.noise_floor_mm


def test_confusable_design_is_ambiguous_never_wrong(sim_model):
    """Poses measured top to bottom at a steady pace: sliders move almost linearly in
    time, so drift and drive scale explain nearly the same thing."""
    verdicts = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        truth = hidden_truth(sim_model, rng, "drift")
        poses = measurement_tour(sim_model, 40, rng)
        poses = poses[np.argsort(-poses[:, 2])]
        obs = simulate_observations(truth, sim_model, poses, rng=rng, t_s=np.arange(1, 41) * 30.0)
        d = diagnose(obs, sim_model, settings=FAST)
        verdicts.append(d)
        assert "drive_scale" not in d.effects
    ambiguous = [d for d in verdicts if d.verdict == "ambiguous"]
    assert ambiguous
    for d in ambiguous:
        assert set(d.ambiguous_between) == {"drift", "drive_scale"} and d.effect is None
        assert any({a, b} == {"drift", "drive_scale"} for a, b, _ in d.confusable)
        assert all(c.status == "rival" for c in d.candidates if c.name in d.ambiguous_between)


def test_too_few_or_bad_poses_are_input_errors(make_session, sim_model):
    _, _, obs = make_session(None, 3, n_poses=40)
    with pytest.raises(InputError, match="at least 8"):
        diagnose(obs.subset(np.arange(5)), sim_model, settings=FAST)
    bad = obs.subset(np.arange(20))
    bad.measured[3, 1] = np.nan
    with pytest.raises(InputError, match="pose\\(s\\) 4"):
        diagnose(bad, sim_model, settings=FAST)


def test_existing_profile_effects_are_refitted_not_tested(make_session, sim_profile):
    truth, _, obs = make_session("drive_scale", 8, vector=np.array([0.005, -0.004, 0.006]))
    data = sim_profile.model_dump()
    data["effects"] = {"drive_scale": {"eps": [0.0, 0.0, 0.0]}}
    model = MachineModel.from_profile(profile_from_dict(data))
    d = diagnose(obs, model, settings=FAST)
    assert d.verdict == "none" and "drive_scale" not in [c.name for c in d.candidates]
    np.testing.assert_allclose(
        d.parameters["drive_scale"]["vector"], [0.005, -0.004, 0.006], atol=5e-4
    )
    assert d.base.heldout_rms_mm < 1.3 * d.noise_floor_mm


def test_effects_the_session_cannot_see_are_listed_as_absorbed(make_session, sim_model):
    from dataclasses import replace

    _, _, obs = make_session(None, 9)
    d = diagnose(replace(obs, t_s=None, directions=None), sim_model, settings=FAST)
    absorbed = {c.name for c in d.candidates if c.status == "absorbed"}
    assert absorbed == {"drift", "backlash"}
    assert d.verdict == "none"
    assert set(to_json(d)["absorbed"]) == {"drift", "backlash"}
    assert "absorbed by the geometry" in to_text(d)
