"""Acceptance: the fixture's first layer, printed by `cdprhost print` over a pty against
`cdprhost sim-device --firmware avr`, completes and executes exactly what the Python
device executes for the same file: the same segments, step totals and device-clock times.

The whole layer is printed (start G-code with homing and heating included: 4,076 segments,
236 s of device time at the AVR's 8,000 steps/s). The hotend starts warm (190 C, a printer
still warm from a print): from cold the plant of thermal_plant.py takes 75 s to 200 C,
which would add most of a minute of simavr time without changing what the test compares.
The AVR runs at 2x real time: at 4x (simavr manages about 3x here) simavr took a whole
core, and on a loaded PC the host, starved beside it, let the queue run dry (an UNDERRUN
at segment 1889 in a `-n 2` run at a load average of about 5); the Python model runs at
25x, so the test takes about two minutes.

The engine build (CDPRHOST_STEP_ENGINE=1) runs the AVR at 1x, so its print takes about
four minutes. Its lead is what its ring of schedule chunks holds, in device time: about
1 s of this layer (the ramps' blocks, 76 entries a second, fill the ring's 128 entries
while the queue holds 20 of its 64 items). The default build's lead is the host's
watermarks (flow.py), in host time: its queue of 128 would hold more than 5 s. At 2x the
engine build's lead therefore shrank to half in host time and the default build's did
not: under the same load the engine build ran dry and the default build did not (FLOW's
buffered motion, a load average of 4-5: engine at 2x p1 0.23 s / p50 0.49 s of host time,
the default at 2x 0.30 / 0.61 s, the engine at 1x 0.40 / 0.74 s; a run that failed: the
host heard nothing for 0.66 s while the device held 1.21 s of motion at 2x).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cdprhost.cli.main import main
from cdprhost.sim import avr_device
from tests.conftest import FIXTURE_GCODE
from tests.e2e.conftest import first_layers

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(900),
]

SPEEDUP = {"python": "25", "avr": "1" if avr_device.STEP_ENGINE else "2"}
#: the Python device announces the firmware's rates, so the host plans the same segments:
#: 8,000 steps/s an axis, and with the engine build its step budget (STEP_BUDGET, 3.3:
#: config.h's TOTAL_STEP_RATE, 80,000 at that rate), which the host names in its notices
ENGINE_BUDGET = ["--total-step-rate", "80000"] if avr_device.STEP_ENGINE else []
EXTRA = {"python": ["--max-step-rate", "8000", *ENGINE_BUDGET], "avr": []}


def _print_on(kind: str, gcode: Path, tmp: Path) -> tuple[dict, list[dict], dict]:
    """Print ``gcode`` on a ``sim-device --firmware kind``: job summary, record, harness stats."""
    record, stats = tmp / f"{kind}.jsonl", tmp / f"{kind}-stats.json"
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", kind]
    cmd += ["--speedup", SPEEDUP[kind], "--record", str(record), *EXTRA[kind]]
    cmd += ["--faults", "hotend_start_c=190"]
    env = {**os.environ, avr_device.STATS_ENV: str(stats)}
    dev = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        pty = dev.stdout.readline().strip() if dev.stdout else ""
        assert pty.startswith("/dev/"), f"sim-device printed {pty!r}"
        report = tmp / f"{kind}.json"
        args = ["print", str(gcode), "--profile", "paper-prototype", "--port", pty]
        assert main([*args, "--json", str(report)]) == 0
    finally:
        dev.send_signal(signal.SIGTERM)
        assert dev.wait(timeout=60) == 0
    rows = [json.loads(line) for line in record.read_text().splitlines() if line.strip()]
    harness = json.loads(stats.read_text()) if stats.exists() else {}
    return json.loads(report.read_text()), rows, harness


def test_first_layer_on_the_avr_equals_the_python_device(tmp_path, monkeypatch):
    if not FIXTURE_GCODE.exists():
        pytest.skip(f"the fixture {FIXTURE_GCODE} is absent (../shared beside the repository)")
    missing = avr_device.toolchain_missing()
    if missing:
        pytest.skip(missing)
    avr_device.build()
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    gcode = first_layers(FIXTURE_GCODE, tmp_path, 1)
    py_job, py_rows, _ = _print_on("python", gcode, tmp_path)
    avr_job, avr_rows, harness = _print_on("avr", gcode, tmp_path)
    assert py_job["status"] == avr_job["status"] == "completed"
    # both slowed the same way, if at all (the second print finds the board already recorded
    # by the first, so it names the board before connecting: the order may differ)
    assert sorted(py_job["notices"]) == sorted(avr_job["notices"])
    assert len(py_rows) > 4000  # the whole first layer, not a prefix
    assert avr_rows == py_rows  # seq, step totals and device-clock time of every segment
    # no timer interrupt lost for good, no pulse dropped
    assert harness, "the harness wrote no figures"
    assert harness.get("unrepaired", 0) == 0 and harness.get("lost_steps", 0) == 0, harness
    assert harness.get("late_pulses", 0) == 0, harness  # no tick ran past its end
