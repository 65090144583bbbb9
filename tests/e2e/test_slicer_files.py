"""Files sliced for other printers print on the embedded device: retargeted, with a
filament change (M600: park, wait for the operator), with an object cancelled."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import JobState, StateChanged
from cdprhost.kinematics import MachineModel
from cdprhost.motion.prepared import Setup
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded

DATA = Path(__file__).resolve().parents[1] / "gcode" / "data" / "thirdparty"


def _print(path, setup, on_state=lambda job, event: None, tmp_path=None):
    profile = load_profile("paper-prototype")
    holder: dict = {}
    job = None

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    def on_event(e):
        if isinstance(e, StateChanged):
            on_state(job, e)

    options = PrintOptions(setup=setup, log_path=None if tmp_path is None else tmp_path / "job.log")
    job = PrintJob(path, profile, factory, options, on_event=on_event)
    result = job.run()
    return result, holder["link"].device.record, profile


def test_a_prusa_mk3s_file_prints_retargeted(tmp_path):
    result, record, profile = _print(
        DATA / "prusaslicer25_mk3s_cube.gcode", Setup(retarget=True), tmp_path=tmp_path
    )
    assert result.status == "completed", result.reason
    assert result.last_layer == 25
    # the extruder fed the file's filament (after its own start block was dropped)
    fed = result.final_steps[3] / profile.extruder.steps_per_mm
    assert 180 < fed < 215  # 205.4 mm at the flow factor 1 (M221 S95 was the MK3's own)


def test_filament_change_parks_and_waits_for_the_operator(tmp_path):
    src = (DATA / "slic3r13_firmware_retraction_tube.gcode").read_text().splitlines()
    third_layer = [i for i, line in enumerate(src) if line.startswith("G1 Z")][3]
    src.insert(third_layer, "M600")
    path = tmp_path / "tube_m600.gcode"
    path.write_text("\n".join(src) + "\n")
    paused = []

    def on_state(job, event):
        if event.state is JobState.PAUSED:
            paused.append(event.reason)
            threading.Timer(0.05, job.request_resume).start()

    result, record, profile = _print(path, Setup(center=True), on_state, tmp_path)
    assert result.status == "completed", result.reason
    assert paused == [f"line {third_layer + 1}: M600: change the filament, then resume"]
    # the effector visited the park point (machine frame) between the layers
    model = MachineModel.from_profile(profile)
    steps = np.array([r["steps"][:3] for r in record])
    park = np.array([*profile.gcode.park_xy_mm, 0.0])
    xy = model.fk(steps / np.asarray(profile.drive.steps_per_mm))[:, :2]
    assert np.min(np.linalg.norm(xy - park[:2], axis=1)) < 0.5


def test_cancelling_an_object_prints_the_other(tmp_path):
    path = DATA / "prusaslicer25_ender3_two_objects_m486.gcode"
    full, _, _ = _print(path, Setup(retarget=True), tmp_path=tmp_path)
    less, _, _ = _print(path, Setup(retarget=True, cancel_objects=("tube_stl",)), tmp_path=tmp_path)
    assert full.status == less.status == "completed"
    assert less.final_steps[3] < 0.8 * full.final_steps[3]
    assert less.print_time_s < full.print_time_s


def _cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "cdprhost", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--speedup", "0"], "--speedup: 0 is outside (0, 100000]"),
        (["--speedup", "-1"], "--speedup: -1 is outside"),
        (["--speedup", "nan"], "--speedup: nan is outside"),
        (["--port", ""], "--port: must not be empty"),
        (["--sim-faults", "bogus=1"], "--sim-faults: unknown key 'bogus'"),
        (["--sim-faults", "latency_ms=nan"], "latency_ms must be a finite number"),
        (["--offset", "1"], "--offset: expected X,Y"),
        (["--offset", "1,inf"], "--offset: X and Y must be finite"),
        (["--resume-from-layer", "0"], "--resume-from-layer: 0 is outside [1, "),
        (["--baud", "-5"], "--baud: -5 is outside [50, "),
    ],
)
def test_bad_options_are_usage_errors_without_traceback(args, fragment, tmp_path):
    r = _cli("print", str(DATA / "prusaslicer25_mk3s_cube.gcode"), "-p", "paper-prototype", *args)
    assert r.returncode == 2, r.stderr
    assert fragment in r.stderr and "Traceback" not in r.stderr


def test_a_port_that_does_not_open_claims_no_resume_point(tmp_path):
    r = _cli(
        "print",
        str(DATA / "prusaslicer25_mk3s_cube.gcode"),
        "-p",
        "paper-prototype",
        "--retarget",
        "--port",
        str(tmp_path / "no-such-port"),
        "--log",
        str(tmp_path / "job.log"),
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr  # a missing port is bad input
    assert "no such port" in r.stdout and "resume point" not in r.stdout


def test_check_cli_places_and_retargets(tmp_path):
    path = str(DATA / "cura413_ender3_cube.gcode")
    refused = _cli("check", path, "-p", "paper-prototype")
    assert refused.returncode == 1
    assert "the part fits with --offset" in refused.stdout and "--retarget" in refused.stdout
    ok = _cli(
        "check", path, "-p", "paper-prototype", "--retarget", "--json", str(tmp_path / "r.json")
    )
    assert ok.returncode == 0, ok.stdout
    assert "retargeted: replaced start lines 1-" in ok.stdout
    assert "the slicer (Cura) says: filament 321.4 mm" in ok.stdout


def test_resume_hint_names_the_requested_layer_when_nothing_printed(tmp_path):
    """Regression: a resumed job that failed at once offered to restart at layer 1."""
    r = _cli(
        "print",
        str(DATA / "prusaslicer25_mk3s_cube.gcode"),
        "-p",
        "paper-prototype",
        "--retarget",
        "--resume-from-layer",
        "20",
        "--yes",
        "--sim-faults",
        "stall_after=400",
        "--log",
        str(tmp_path / "job.log"),
    )
    assert r.returncode == 1, r.stdout + r.stderr
    # layer 20 had begun when the device stalled: the hint names it, not layer 1
    assert "restart with --resume-from-layer 20)" in r.stdout
