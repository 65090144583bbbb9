"""`profile export-firmware --to klipper`: the exported winch config against our kinematics."""

from __future__ import annotations

import configparser
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile, save_profile
from cdprhost.profile.loader import profile_from_dict

EFFECTS = {
    "cable_elasticity": {"EA": 20000.0},
    "drive_scale": {"eps": [0.004, -0.003, 0.002]},
    "backlash": {"beta": [0.05, 0.04, 0.06]},
    "drift": {"rho": [1e-5, -2e-5, 0.0]},
}


def _export(profile_ref: str | Path, out: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cdprhost", "profile", "export-firmware", str(profile_ref)]
        + ["--to", "klipper", "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )


def _profile_with(tmp_path: Path, effects: dict[str, dict[str, object]], name: str) -> Path:
    data = load_profile("paper-prototype").model_dump()
    data["effects"] = effects
    data["name"] = name
    data["build_volume"]["bed_origin"] = [3.0, -2.0, 110.0]  # a shifted G-code frame
    path = tmp_path / f"{name}.toml"
    save_profile(profile_from_dict(data), path)
    return path


def _klipper_steps(cfg: configparser.ConfigParser, points: np.ndarray) -> np.ndarray:
    """Klipper's winch step positions at G-code ``points``, relative to the home point
    it is told at G28 (what its itersolve computes: stepper position = |P - anchor|)."""
    home = np.array([float(cfg["homing_override"][f"set_position_{a}"]) for a in "xyz"])
    steps = []
    for k in "abc":
        sec = cfg[f"stepper_{k}"]
        anchor = np.array([float(sec[f"anchor_{a}"]) for a in "xyz"])
        step = float(sec["rotation_distance"]) / (
            float(sec["full_steps_per_rotation"]) * float(sec["microsteps"])
        )
        dist = np.linalg.norm(points - anchor, axis=1) - np.linalg.norm(home - anchor)
        steps.append(dist / step)
    return np.column_stack(steps)


def _read(path: Path) -> configparser.ConfigParser:
    cfg = configparser.ConfigParser(inline_comment_prefixes=("#",))
    cfg.read_string(path.read_text())
    return cfg


@pytest.mark.parametrize("effects", [{}, {"drive_scale": EFFECTS["drive_scale"]}])
def test_the_exported_winch_config_moves_as_our_kinematics_within_a_micrometre(tmp_path, effects):
    ref = _profile_with(tmp_path, effects, "folded" if effects else "ideal")
    out = tmp_path / "printer.cfg"
    run = _export(ref, out)
    assert run.returncode == 0, run.stderr
    assert "every one expressed" in run.stdout
    cfg = _read(out)
    assert cfg["printer"]["kinematics"] == "winch"
    profile = load_profile(ref)
    model = MachineModel.from_profile(profile)
    origin = np.asarray(profile.build_volume.bed_origin)
    grid = workspace_grid(model)  # machine frame
    assert len(grid) > 200
    ours = model.ik(grid) * model.steps_per_mm  # absolute steps, home at 0
    theirs = _klipper_steps(cfg, grid - origin)
    # agreement in position: step differences as mm of cable, then through the Jacobian
    # bound (a cable-length error of d moves the point by at most ~d / sigma_min)
    cable_err_mm = np.abs(ours - theirs) / model.steps_per_mm
    assert cable_err_mm.max() < 1e-4
    # and directly: Klipper's steps put our machine where Klipper wanted it
    reached = model.fk(theirs / model.steps_per_mm)
    assert np.linalg.norm(reached - grid, axis=1).max() < 1e-3  # 1 um


def test_a_profile_with_effects_names_what_klipper_drops(tmp_path):
    ref = _profile_with(tmp_path, EFFECTS, "calibrated")
    out = tmp_path / "printer.cfg"
    run = _export(ref, out)
    assert run.returncode == 0, run.stderr
    text = out.read_text()
    for name in ("cable_elasticity", "backlash", "drift"):
        line = next(ln for ln in run.stdout.splitlines() if ln.strip().startswith(name))
        assert "um rms" in line and "um max" in line
        assert f"#  - {name}: not expressed" in text
    assert "drive_scale folded into rotation_distance" in run.stdout
    # the backlash error is of the order of the lash itself, the drift of rho * 1 h
    backlash = next(ln for ln in run.stdout.splitlines() if "backlash" in ln)
    rms_um = float(backlash.split("error ")[1].split(" um")[0])
    assert 20 < rms_um < 400


def test_bad_target_is_a_usage_error(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "cdprhost", "profile", "export-firmware", "paper-prototype"]
        + ["--to", "marlin", "--out", str(tmp_path / "x.cfg")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 2 and "klipper" in run.stderr
