"""A lossy pty (1 % corruption + 1 % drop per byte, the project's ``--faults``; issue 30),
shortened for CI: the handshake at 10x, and the fixture's start (heating, homing and the
first moves of layer 1) printed at 10x with a record equal to the embedded print's. The
full acceptance runs (20 handshakes at 1x and 10x, the first two layers at 10x in five
seeds, the head at 1x) are ``bench/lossy_link.py``."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import pytest

from cdprhost.cli.main import main
from cdprhost.link import open_link
from tests.e2e.conftest import print_embedded

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")

LOSSY = "corrupt=0.01,drop=0.01"


def head(gcode, out_dir, moves=60):
    """The fixture's start through the ``moves``-th extruding move of layer 1."""
    lines, seen, layer = [], 0, False
    for line in gcode.read_text().splitlines():
        lines.append(line)
        layer = layer or line.startswith(";LAYER_CHANGE")
        if layer and line.startswith("G1 ") and " E" in line:
            seen += 1
            if seen >= moves:
                break
    path = out_dir / "head.gcode"
    path.write_text("\n".join([*lines, "M104 S0", "M140 S0"]) + "\n")
    return path


def device(*args):
    dev = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    port = dev.stdout.readline().strip()
    assert port.startswith("/dev/"), dev.stderr.read() if dev.poll() is not None else port
    return dev, port


def stop(dev):
    dev.send_signal(signal.SIGTERM)
    assert dev.wait(timeout=20) == 0


@pytest.mark.parametrize("seed", [5, 6])  # seeds whose handshake failed within the old 2 s
def test_handshake_on_a_lossy_pty(seed):
    dev, port = device("--speedup", "10", "--faults", f"{LOSSY},seed={seed}")
    try:
        link = open_link(port)
        try:
            assert link.request_status() is not None
        finally:
            link.close()
    finally:
        stop(dev)


def test_the_fixture_head_prints_exactly_over_a_lossy_pty_at_10x(
    fixture_gcode, tmp_path, monkeypatch
):
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    gcode = head(fixture_gcode, tmp_path)
    embedded = print_embedded(gcode)
    assert embedded.result.status == "completed"
    record = tmp_path / "record.jsonl"
    dev, port = device("--speedup", "10", "--record", str(record), "--faults", f"{LOSSY},seed=2")
    try:
        report = tmp_path / "report.json"
        code = main(
            ["print", str(gcode), "--profile", "paper-prototype", "--port", port]
            + ["--json", str(report)]
        )
    finally:
        stop(dev)
    result = json.loads(report.read_text())
    assert code == 0 and result["status"] == "completed", result.get("reason")
    assert result["retransmits"] > 0  # the faults did bite
    rows = [json.loads(line) for line in record.read_text().splitlines()]
    assert rows == embedded.record  # seq, steps and device time all identical
