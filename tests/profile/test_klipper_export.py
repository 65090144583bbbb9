"""`profile export-firmware --to klipper`: the exported winch config against our kinematics."""

from __future__ import annotations

import configparser
import os
import re
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


FIXTURE = (
    Path(__file__).resolve().parents[2] / ".." / "shared" / "fixtures" / "part-prusaslicer.gcode"
)


def test_the_export_declares_the_extruder_bed_and_fan_on_ramps_pins(tmp_path):
    """What a sliced file needs in Klipper: an [extruder] (else "Extrude when no extruder
    present"), the heaters and sensors (M104/M109/M140/M190), the fan (M106/M107), all on the
    RAMPS 1.4 pins our firmware uses, and a G28 that needs no module Klipper leaves off."""
    out = tmp_path / "printer.cfg"
    assert _export("paper-prototype", out).returncode == 0
    cfg = _read(out)
    profile = load_profile("paper-prototype")
    ex = cfg["extruder"]
    assert (ex["step_pin"], ex["dir_pin"], ex["enable_pin"]) == ("PA4", "PA6", "!PA2")
    assert (ex["heater_pin"], ex["sensor_pin"]) == ("PB4", "PK5")  # D10, A13
    steps = float(ex["full_steps_per_rotation"]) * float(ex["microsteps"])
    assert steps / float(ex["rotation_distance"]) == pytest.approx(profile.extruder.steps_per_mm)
    assert float(ex["filament_diameter"]) == profile.extruder.filament_diameter_mm
    assert float(ex["max_temp"]) == profile.heaters.hotend_max_c
    assert ex["control"] == "pid" and float(ex["pid_Kp"]) > 0
    bed = cfg["heater_bed"]
    assert (bed["heater_pin"], bed["sensor_pin"]) == ("PH5", "PK6")  # D8, A14
    assert float(bed["max_temp"]) == profile.heaters.bed_max_c
    assert ex["sensor_type"] == bed["sensor_type"] == "Generic 3950"  # 100k, beta 3950
    assert cfg["fan"]["pin"] == "PH6"  # D9
    home = cfg["homing_override"]
    assert all(f"set_position_{a}" in home for a in "xyz")  # G28 declares the position
    force_move = cfg.has_section("force_move") and cfg["force_move"].getboolean(
        "enable_force_move", False
    )
    assert "SET_KINEMATIC_POSITION" not in home["gcode"] or force_move


def test_the_export_uses_the_profiles_pid_gains(tmp_path):
    data = load_profile("paper-prototype").model_dump()
    data["name"] = "tuned"
    data["heaters"]["hotend_pid"] = {"kp": 25.5, "ki": 1.5, "kd": 100.25}
    data["heaters"]["bed_pid"] = {"kp": 70.0, "ki": 1.2, "kd": 900.0}
    ref = tmp_path / "tuned.toml"
    save_profile(profile_from_dict(data), ref)
    out = tmp_path / "printer.cfg"
    assert _export(ref, out).returncode == 0
    cfg = _read(out)
    assert [float(cfg["extruder"][k]) for k in ("pid_Kp", "pid_Ki", "pid_Kd")] == [
        25.5,
        1.5,
        100.25,
    ]
    assert cfg["heater_bed"]["control"] == "pid" and float(cfg["heater_bed"]["pid_Kd"]) == 900.0


def test_a_sliced_file_runs_in_klippers_batch_mode(tmp_path):
    """Against Klipper itself, when it is on this machine: ``CDPRHOST_KLIPPER`` a Klipper
    checkout whose ``out/klipper.dict`` is built (atmega2560), ``CDPRHOST_KLIPPER_PYTHON``
    a Python with its packages. The head of a PrusaSlicer file (start G-code, G28, heating,
    the first layers' extrusion) runs to its end with no error and no unknown command."""
    klipper, python = _klipper_here()
    out = tmp_path / "printer.cfg"
    assert _export("paper-prototype", out).returncode == 0
    head = tmp_path / "head.gcode"
    with open(FIXTURE, encoding="utf-8") as fh:
        head.write_text("".join(line for _, line in zip(range(4000), fh)))
    assert "G28" in head.read_text() and " E" in head.read_text()
    log = tmp_path / "klippy.log"
    run = subprocess.run(
        [python, str(klipper / "klippy" / "klippy.py"), str(out), "-i", str(head)]
        + ["-o", os.devnull, "-d", str(klipper / "out" / "klipper.dict"), "-l", str(log)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    text = log.read_text()
    assert run.returncode == 0, text[-2000:]
    refusals = re.findall(r"Unknown command.*|Extrude (?:when|below|exceeds).*|Move exceed.*", text)
    assert refusals == [], refusals[:5]
    assert "Exiting (print time" in text


def _klipper_here() -> tuple[Path, str]:
    klipper = os.environ.get("CDPRHOST_KLIPPER")
    if not klipper or not (Path(klipper) / "out" / "klipper.dict").is_file():
        pytest.skip("Klipper is not here (set CDPRHOST_KLIPPER to a built checkout)")
    return Path(klipper), os.environ.get("CDPRHOST_KLIPPER_PYTHON", sys.executable)


def _batch_steps(klipper: Path, python: str, cfg: Path, gcode: Path, tmp: Path) -> list[int]:
    """The step position of each stepper (oid order) after Klipper ran ``gcode``: its
    queue_step and set_next_step_dir commands summed."""
    dictionary = str(klipper / "out" / "klipper.dict")
    serial = tmp / "out.serial"
    subprocess.run(
        [python, str(klipper / "klippy" / "klippy.py"), str(cfg), "-i", str(gcode)]
        + ["-o", str(serial), "-d", dictionary, "-l", str(tmp / "klippy.log")],
        check=True,
        capture_output=True,
        timeout=300,
    )
    dump = subprocess.run(
        [python, str(klipper / "klippy" / "parsedump.py"), dictionary, str(serial)],
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    ).stdout
    pos = [0] * 4
    sign = [1] * 4
    for line in dump.splitlines():
        fields = dict(kv.split("=", 1) for kv in line.split()[1:] if "=" in kv)
        if line.startswith("set_next_step_dir"):
            sign[int(fields["oid"])] = 1 if fields["dir"] == "1" else -1
        elif line.startswith("queue_step"):
            pos[int(fields["oid"])] += sign[int(fields["oid"])] * int(fields["count"])
    return pos


def test_klipper_itself_steps_as_our_kinematics(tmp_path):
    """Klipper's batch mode, G28 then one move to each of a few workspace points: the steps it
    emits are ours, to the step (the config's G28 declares the same home)."""
    klipper, python = _klipper_here()
    out = tmp_path / "printer.cfg"
    assert _export("paper-prototype", out).returncode == 0
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    origin = np.asarray(profile.build_volume.bed_origin)
    grid = workspace_grid(model)
    points = grid[np.random.default_rng(7).choice(len(grid), 4, replace=False)]
    for point in points:
        g = point - origin
        gcode = tmp_path / "move.gcode"
        gcode.write_text(f"G28\nG1 X{g[0]:.6f} Y{g[1]:.6f} Z{g[2]:.6f} F3000\nM400\n")
        theirs = _batch_steps(klipper, python, out, gcode, tmp_path)[:3]
        ours = np.rint(model.ik(point[None])[0] * model.steps_per_mm).astype(int)
        assert list(ours) == theirs, (point, ours, theirs)
