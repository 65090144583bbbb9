"""The measuring system's accuracy at each place (the same in every frame of a take, so no
take's scatter shows it) belongs in the noise floor (calibration-session.md): a mocap
session with 0.05 mm of it and a hidden drive_scale is diagnosed ``named``, with the
accuracy estimated and reported; declared ``accuracy_mm`` is used as given."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.session import load_session
from cdprhost.diagnosis.noise_floor import variance_component
from cdprhost.diagnosis.workflow import FAST, diagnose
from cdprhost.effects.base import MotionContext
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times
from cdprhost.sim.synthetic_session import write_synthetic_session
from tests.diagnosis.sessions import SESSION_MOCAP


def write_accuracy_session(directory, model, effect, seed, accuracy_mm=0.05, n_poses=40):
    rng = np.random.default_rng(seed)
    truth = hidden_truth(model, rng, effect)
    poses = measurement_tour(model, n_poses, rng)
    t = session_times(n_poses, rng)
    s_cmd, dirs = commanded_path(model, poses)
    actual = truth.fk(s_cmd, MotionContext(t_s=t, directions=dirs))
    write_synthetic_session(
        directory,
        actual,
        poses,
        s_cmd,
        t,
        dirs.astype(int),
        "paper-simulation",
        noise_mm=accuracy_mm,  # one offset per take: the system's accuracy at that place
        realism=dataclasses.replace(SESSION_MOCAP, jitter_mm=0.12),
        n_frames=240,
        rate_hz=120.0,
        seed=seed + 5,
    )
    return truth


def test_variance_component_solves_the_chi_square():
    r2 = np.array([0.01, 0.02, 0.005, 0.03])
    sig = np.full(4, 0.02)
    s = variance_component(r2, sig, 4)
    assert np.isclose(np.sum(r2 / (sig**2 + s**2)), 4.0, rtol=1e-6)
    assert variance_component(r2 * 1e-4, sig, 4) == 0.0


@pytest.mark.slow
def test_hidden_drive_scale_with_accuracy_error_is_named(tmp_path, sim_model):
    truth = write_accuracy_session(tmp_path / "s", sim_model, "drive_scale", 0)
    meas = load_session(tmp_path / "s").measure()
    noise = meas.noise(sim_model.steps_per_mm)
    assert noise.source == "takes" and noise.typical_mm < 0.03  # the takes alone: too low
    d = diagnose(meas.observations(noise), sim_model, noise, FAST)
    assert d.verdict == "named" and d.effects == ("drive_scale",), (d.verdict, d.where)
    assert d.noise.source == "takes + accuracy (fit)"
    assert 0.03 < d.noise.extra_mm < 0.08, d.noise.extra_mm
    vec = np.asarray(d.parameters["drive_scale"]["vector"])
    se = np.asarray(d.parameters["drive_scale"]["stderr"])
    true_vec = truth.effects.vectors[0]
    assert np.all(np.abs(vec - true_vec) <= 3 * se), (vec, true_vec, se)
    assert d.final.heldout_rms_mm <= 1.3 * d.noise_floor_mm
    assert d.base.heldout_rms_mm > 2 * d.final.heldout_rms_mm  # the gap shrinks


def test_declared_accuracy_is_used(tmp_path, sim_model):
    write_accuracy_session(tmp_path / "s", sim_model, None, 3, n_poses=10)
    toml = tmp_path / "s" / "session.toml"
    text = toml.read_text()
    toml.write_text(text.replace("[mocap]\n", "[mocap]\naccuracy_mm = 0.05\n", 1))
    meas = load_session(tmp_path / "s").measure()
    noise = meas.noise(sim_model.steps_per_mm)
    assert noise.extra_mm == 0.05 and "declared" in noise.source
