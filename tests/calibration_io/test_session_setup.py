"""Starting a session from scratch: markers of a take, role guesses, validated configuration."""

from __future__ import annotations

import pytest

from cdprhost.calibration.mocap.setup import markers_in_take, mocap_config, suggest_roles
from cdprhost.errors import InputError
from tests.calibration_io.helpers import DATA


def test_markers_roles_and_configuration_from_one_take():
    names = markers_in_take(DATA / "motive_1.25_parent_mm.csv")
    base, eff = suggest_roles(names)
    assert base == ["Base:F1", "Base:F2", "Base:F3"] and eff == ["EE:E1", "EE:E2", "EE:E3"]
    positions = {"Base:F1": (0, 300, 0), "Base:F2": (-259.8, -150, 0), "Base:F3": (259.8, -150, 0)}
    config = mocap_config(positions, eff, (0, 0, -12), acceptance={"max_drift_mm": 0.1})
    assert config.acceptance.max_drift_mm == 0.1 and config.effector.offset == (0, 0, -12)


def test_every_problem_is_listed_at_once():
    with pytest.raises(InputError) as err:
        mocap_config({"A": (0, 0, 0), "B": (1, 0, 0)}, ["A"], (0, 0), format="fbx")
    text = str(err.value)
    assert "base_markers: need at least 3" in text and "format" in text and "offset" in text
