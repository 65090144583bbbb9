"""Virtual motion capture: takes of where the hidden true machine really is."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.mocap.readers import read_take
from cdprhost.calibration.mocap.takes import measure_effector
from cdprhost.errors import InputError
from cdprhost.kinematics import MachineModel
from cdprhost.profile import save_profile
from cdprhost.sim.virtual_mocap import VirtualMocap, make_observer, mocap_config

from .conftest import paper_truth_geometry


def test_factory_needs_both_options_or_none(tmp_path):
    assert make_observer(None, None) is None
    with pytest.raises(InputError, match="--truth needs --mocap-dir"):
        make_observer("paper-simulation", None)
    with pytest.raises(InputError, match="--mocap-dir needs --truth"):
        make_observer(None, tmp_path)


def test_take_measures_the_true_effector(sim_profile, tmp_path):
    g = paper_truth_geometry()
    save_profile(
        sim_profile.with_geometry(g.outlets, g.initial_lengths, name="truth"), tmp_path / "t.toml"
    )
    obs = make_observer(tmp_path / "t.toml", tmp_path / "mocap", noise_mm=0.0)
    truth = MachineModel.from_profile(sim_profile).with_geometry(g)
    steps = (np.array([-20.0, -30.0, -25.0]) * 400).astype(int)
    path = obs.on_settled((*steps, 123), 12.5)
    assert path.name == "take-0001.csv" and path.is_file()
    m = measure_effector(read_take(path), mocap_config().mocap)
    want = truth.fk(truth.sliders_from_steps(steps)[None])[0]
    np.testing.assert_allclose(m.point, want, atol=0.02)
    assert obs.on_settled((*steps, 0), 13.0).name == "take-0002.csv"


@pytest.mark.parametrize("fmt", ["vicon-csv", "c3d"])
def test_other_formats(sim_model, tmp_path, fmt):
    obs = VirtualMocap(sim_model, tmp_path, format=fmt, noise_mm=0.0)
    path = obs.on_settled((0, 0, 0, 0), 1.0)
    m = measure_effector(read_take(path), mocap_config(format=fmt).mocap)
    np.testing.assert_allclose(m.point, sim_model.fk(np.zeros((1, 3)))[0], atol=0.02)


def test_backlash_uses_directions_from_the_device_record(sim_profile, tmp_path):
    truth = MachineModel.from_profile(
        sim_profile.model_copy(update={"effects": {"backlash": {"beta": [0.5, 0.5, 0.5]}}})
    )
    obs = VirtualMocap(truth, tmp_path, noise_mm=0.0)
    record = [
        {"steps": [0, 0, 0, 0]},
        {"steps": [-4000, -4000, -4000, 0]},
        {"steps": [-4400, -3600, -4000, 0]},
    ]
    obs.attach_record(record)
    steps = np.array([-4400, -3600, -4000])
    got = obs.effector_point(steps, 0.0, obs._record_directions())
    np.testing.assert_array_equal(obs._record_directions(), [-1, 1, -1])
    s_act = truth.sliders_from_steps(steps) - 0.5 * np.array([-1, 1, -1])
    want = MachineModel.from_profile(sim_profile).fk(s_act[None])[0]
    np.testing.assert_allclose(got, want, atol=1e-9)
