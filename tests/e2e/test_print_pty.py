"""`cdprhost print --port` against `cdprhost sim-device` on a real pty, through pyserial.

The fixture's first layer is printed over the pty on a clean device and on a device
that corrupts, drops and duplicates bytes; both device records must equal the record
of the same file printed on the embedded device (and so each other).

Both pty devices start with the hotend at the file's 200 C (``hotend_start_c``): the M109
heat-up from cold (about 75 s of device time: 9 s of wall time at the faulty line's 8x)
moves nothing, and the records compare only what moved.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from cdprhost.cli.main import main
from tests.e2e.conftest import first_layers, print_embedded

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")


#: device time per second of wall time: the clean line at 25x; the faulty one at 8x, since
#: each lost frame costs the host its resend timeout in wall time, which at 25x is device
#: time enough to drain the queue on a loaded test machine (an underrun, not a wrong record)
SPEEDUP = {"clean": "25", "faulty": "8"}


def _print_over_pty(gcode, tmp_path, name, faults=None):
    record = tmp_path / f"{name}.jsonl"
    cmd = [
        sys.executable,
        "-m",
        "cdprhost",
        "sim-device",
        "--speedup",
        SPEEDUP[name],
        "--record",
        str(record),
    ]
    warm = "hotend_start_c=200"
    cmd += ["--faults", f"{faults},{warm}" if faults else warm]
    dev = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        pty = dev.stdout.readline().strip()
        assert pty.startswith("/dev/"), (
            f"sim-device printed {pty!r}: {dev.stderr.read() if dev.poll() is not None else ''}"
        )
        report = tmp_path / f"{name}.json"
        code = main(
            [
                "print",
                str(gcode),
                "--profile",
                "paper-prototype",
                "--port",
                pty,
                "--json",
                str(report),
            ]
        )
        result = json.loads(report.read_text())
    finally:
        dev.send_signal(signal.SIGTERM)
        assert dev.wait(timeout=20) == 0
    rows = [json.loads(line) for line in record.read_text().splitlines()]
    return code, result, rows


def test_pty_prints_equal_the_embedded_print_with_and_without_faults(
    fixture_gcode, tmp_path, monkeypatch
):
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    gcode = first_layers(fixture_gcode, tmp_path, 1)
    embedded = print_embedded(gcode)
    assert embedded.result.status == "completed"
    want = [(r["seq"], r["steps"]) for r in embedded.record]
    code, clean, rows = _print_over_pty(gcode, tmp_path, "clean")
    assert code == 0 and clean["status"] == "completed"
    assert [(r["seq"], r["steps"]) for r in rows] == want
    code, faulty, frows = _print_over_pty(
        gcode, tmp_path, "faulty", "corrupt=0.001,drop=0.001,dup=0.001,seed=7"
    )
    assert code == 0 and faulty["status"] == "completed"
    assert frows == rows  # seq, steps and device time all identical
    assert faulty["retransmits"] > clean["retransmits"]
    assert os.path.getsize(tmp_path / "faulty.jsonl") == os.path.getsize(tmp_path / "clean.jsonl")
