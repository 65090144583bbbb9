"""End to end: simulator -> mocap files -> `cdprhost diagnose` -> augmented profile -> printing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.calibration.fitting import CableModelFit
from cdprhost.cli.main import main
from cdprhost.diagnosis.session_input import load_session_data
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile
from cdprhost.sim.measurement import achieved_points
from tests.diagnosis.sessions import write_hidden_session

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


def rms_3d(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.mark.parametrize(
    ("effect", "fmt", "seed"),
    [("drive_scale", "motive-csv", 31), ("cable_elasticity", "qualisys-tsv", 32)],
)
def test_diagnose_names_the_effect_and_the_profile_prints_better(
    tmp_path, sim_model, effect, fmt, seed, capsys
):
    session = tmp_path / "session"
    truth = write_hidden_session(session, sim_model, effect, seed, format=fmt)
    report, out, plot = tmp_path / "r.json", tmp_path / "augmented.toml", tmp_path / "gap.png"
    rc = main(
        [
            "diagnose",
            str(session),
            "--profile",
            "paper-simulation",
            "--json",
            str(report),
            "--out",
            str(out),
            "--plot",
            str(plot),
        ]
    )
    assert rc == 0
    printed = capsys.readouterr().out
    assert f"verdict: named: {effect}" in printed and "held-out mm" in printed

    result = json.loads(report.read_text())
    assert set(result) >= CONTRACT_FIELDS
    assert result["verdict"] == "named" and result["effect"] == effect
    assert {c["name"] for c in result["candidates"]} == {
        "cable_elasticity",
        "drive_scale",
        "backlash",
        "drift",
    }
    assert (
        result["heldout_rms_after_mm"]
        <= 1.3 * result["noise_floor_mm"]
        < result["heldout_rms_before_mm"]
    )
    assert effect in result["parameters"] and result["where"]
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    augmented = load_profile(out)
    assert set(augmented.effects) == {effect}
    commanding = MachineModel.from_profile(augmented)
    # printing side: the same session calibrated without the effect is the baseline
    data = load_session_data(session)
    base = CableModelFit().fit(data.observations, sim_model).model_
    grid = workspace_grid(sim_model, spacing_mm=30.0)
    err_base = rms_3d(achieved_points(truth, base, grid), grid)
    err_aug = rms_3d(achieved_points(truth, commanding, grid), grid)
    assert err_aug < 0.5 * err_base
    assert err_aug < 0.1


def test_clean_session_says_none_and_exits_zero(tmp_path, sim_model):
    session = tmp_path / "clean"
    write_hidden_session(session, sim_model, None, 33, format="vicon-csv")
    report = tmp_path / "r.json"
    assert (
        main(["diagnose", str(session), "-p", "paper-simulation", "--json", str(report), "--quiet"])
        == 0
    )
    result = json.loads(report.read_text())
    assert result["verdict"] == "none" and result["effect"] is None
    assert result["where"].startswith("no disagreement beyond the noise floor")
    assert result["noise"]["source"] == "takes"


def test_declared_noise_is_read_from_session_toml(tmp_path, sim_model):
    session = tmp_path / "declared"
    write_hidden_session(session, sim_model, None, 34, n_poses=12)
    toml = session / "session.toml"
    toml.write_text(toml.read_text().replace("[session]\n", "[session]\nnoise_mm = 0.06\n", 1))
    data = load_session_data(session)
    assert data.noise.source == "takes + declared" and data.noise.extra_mm == 0.06
    np.testing.assert_allclose(data.observations.sigma_mm, np.hypot(data.noise.take_mm, 0.06))
    assert len(data.observations) == 12
    toml.write_text(toml.read_text().replace("noise_mm = 0.06", "noise_mm = -1"))
    assert main(["diagnose", str(session), "-p", "paper-simulation", "-q"]) == 2


def test_bad_input_exits_two(tmp_path, sim_model, capsys):
    assert main(["diagnose", str(tmp_path / "missing"), "-p", "paper-simulation"]) == 2
    assert "missing" in capsys.readouterr().err
    session = tmp_path / "small"
    write_hidden_session(session, sim_model, None, 35, n_poses=5)
    assert main(["diagnose", str(session), "-p", "paper-simulation"]) == 2
    assert "at least 8" in capsys.readouterr().err
    assert (
        main(["diagnose", str(session), "-p", "paper-simulation", "--effects", "warp_drive"]) == 2
    )
    assert "warp_drive" in capsys.readouterr().err
    assert main(["diagnose", str(session), "-p", "no-such-profile"]) == 2


def test_out_of_catalogue_effect_is_unexplained_end_to_end(tmp_path, sim_model):
    from tests.diagnosis.hidden_effects import PeriodicLeadError

    session = tmp_path / "lead"
    vec = np.array([0.15, 0.12, 0.18, 8.0, 0.4, 2.0, 4.1])
    write_hidden_session(session, sim_model, PeriodicLeadError(), 36, vector=vec, format="c3d")
    report, out = tmp_path / "r.json", tmp_path / "aug.toml"
    assert (
        main(
            [
                "diagnose",
                str(session),
                "-p",
                "paper-simulation",
                "--json",
                str(report),
                "--out",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    result = json.loads(report.read_text())
    assert result["verdict"] == "unexplained" and result["effect"] is None
    assert "repeat with slider position" in result["where"]
    assert result["chi2_after"]["p_value"] < 1e-3
    assert load_profile(out).calibration["diagnosis"]["verdict"] == "unexplained"


@pytest.mark.parametrize(
    ("pair", "fmt", "seed"),
    [
        (("drive_scale", "backlash"), "qualisys-tsv", 301),
        (("cable_elasticity", "drift"), "c3d", 302),
    ],
)
def test_two_effects_at_once_are_both_named(tmp_path, sim_model, pair, fmt, seed, capsys):
    session = tmp_path / "two"
    write_hidden_session(
        session, sim_model, list(pair), seed, format=fmt, rate_hz=240.0, duration_s=3.0
    )
    report = tmp_path / "r.json"
    assert main(["diagnose", str(session), "-p", "paper-simulation", "--json", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["verdict"] == "named" and set(data["effects"]) == set(pair)
    assert data["effect"] == data["effects"][0]
    steps = data["steps"]
    assert [s["added"] for s in steps] == [None, *data["effects"]]
    held = [s["heldout_rms_mm"] for s in steps]
    assert held[0] > held[1] > held[2]  # each step closes part of the gap...
    assert held[2] <= 1.3 * steps[2]["noise_floor_mm"]  # ...and the last closes it
    out = capsys.readouterr().out
    assert "forward selection: the gap after each step" in out
    assert f"geometry + {data['effects'][0]} + {data['effects'][1]}" in out
