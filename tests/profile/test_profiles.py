import math

import numpy as np
import pytest

from cdprhost.errors import InputError
from cdprhost.profile import load_profile, profile_from_dict, profile_to_toml
from cdprhost.profile.loader import shipped_names


def test_shipped_profiles_carry_the_spec_numbers():
    assert {"paper-simulation", "paper-prototype"} <= set(shipped_names())
    sim = load_profile("paper-simulation")
    assert sim.geometry.outlets[1] == (263.0, -148.0, 77.0)
    assert sim.geometry.initial_lengths == (390.0, 391.5, 389.0)
    proto = load_profile("paper-prototype")
    assert proto.geometry.outlets[0] == (253.90, -146.50, 77.5)
    for p in (sim, proto):
        assert p.drive.steps_per_mm == (400.0, 400.0, 400.0)
        assert p.statics.spring_rate_n_per_mm == 0.15 and p.statics.spring_preload_n == 25.0
        assert p.build_volume.bed_origin == (0.0, 0.0, 110.0)
        assert p.extruder.steps_per_mm == 95.5
        assert math.isclose(p.motion.junction_deviation_mm, 25 * (2**0.5 - 1) / 2000)


def test_toml_round_trip(tmp_path):
    sim = load_profile("paper-simulation")
    path = tmp_path / "copy.toml"
    path.write_text(profile_to_toml(sim))
    assert load_profile(path) == sim


def _data():
    return load_profile("paper-simulation").model_dump()


@pytest.mark.parametrize(
    "mutate, key",
    [
        (lambda d: d["geometry"].pop("outlets"), "geometry.outlets: missing"),
        (lambda d: d["drive"].update(spm=1), "drive.spm: unknown key"),
        (lambda d: d["drive"].update(steps_per_mm=(-400, 400, 400)), "drive.steps_per_mm.0"),
        (lambda d: d["statics"].update(effector_mass_kg=float("nan")), "statics.effector_mass_kg"),
        (lambda d: d["geometry"].update(outlets=((0, 0, 0), (1, 1, 1), (2, 2, 2))), "collinear"),
        (
            lambda d: d["geometry"].update(
                outlets=((-258, -149, 120), (263, -148, 77), (0, 301, 78))
            ),
            "not below the build volume",
        ),
        (lambda d: d["build_volume"].update(side_mm="wide"), "build_volume.side_mm"),
    ],
)
def test_invalid_profiles_name_the_key(mutate, key):
    data = _data()
    mutate(data)
    with pytest.raises(InputError) as err:
        profile_from_dict(data, source="bad.toml")
    assert key in str(err.value) and err.value.exit_code == 2


def test_every_problem_is_listed_once():
    data = _data()
    data["drive"]["steps_per_mm"] = (-1, -2, 400)
    data["statics"]["tension_max_n"] = float("inf")
    with pytest.raises(InputError) as err:
        profile_from_dict(data)
    assert len(err.value.problems) == 3


def test_resolution_by_user_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path))
    (tmp_path / "mine.toml").write_text(
        profile_to_toml(load_profile("paper-prototype")).replace(
            'name = "paper-prototype"', 'name = "mine"'
        )
    )
    assert load_profile("mine").name == "mine"
    with pytest.raises(InputError, match="unknown profile 'nope'"):
        load_profile("nope")


def test_with_geometry_replaces_parameters():
    sim = load_profile("paper-simulation")
    new = sim.with_geometry(
        np.zeros((3, 3)) + [[-260, -150, 78], [260, -150, 78], [0, 300, 78]], [392, 392, 392]
    )
    assert new.geometry.initial_lengths == (392.0, 392.0, 392.0)
