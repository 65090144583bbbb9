"""A device reset mid-print: status failed, exit 1, last line named, resume point; then resume."""

from __future__ import annotations

import json

import pytest

from cdprhost.cli.main import main
from cdprhost.job.resume import ResumePoint
from tests.e2e.conftest import first_layers


@pytest.mark.timeout(240)  # a reset ends the job promptly (not asserted: shared machine)
def test_reset_mid_print_fails_naming_the_line_then_resume_completes(
    fixture_gcode, tmp_path, monkeypatch, capsys
):
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    path = first_layers(fixture_gcode, tmp_path, 3, ("M104 S0", "G28 X0"))
    report = tmp_path / "job.json"
    code = main(
        [
            "print",
            str(path),
            "--profile",
            "paper-prototype",
            "--sim-faults",
            "reset_after=1500",
            "--json",
            str(report),
        ]
    )
    assert code == 1
    data = json.loads(report.read_text())
    assert data["status"] == "failed" and "the device reset" in data["reason"]
    assert "DeviceReset" not in data["reason"]  # the operator reads it: no class name
    assert data["segments"] <= 1500 and data["last_line"] > 0 and data["last_layer"] >= 1
    out = capsys.readouterr().out
    assert f"last line: {data['last_line']}" in out
    point = ResumePoint.load(data["resume_file"])
    assert point.last_line == data["last_line"] and point.suggested_layer == data["last_layer"]

    again = tmp_path / "resume.json"
    code = main(
        [
            "print",
            str(path),
            "--profile",
            "paper-prototype",
            "--resume-from-layer",
            str(point.suggested_layer),
            "--yes",
            "--json",
            str(again),
        ]
    )
    resumed = json.loads(again.read_text())
    assert code == 0 and resumed["status"] == "completed"
    assert resumed["last_layer"] == 3


def test_resume_needs_confirmation_without_yes(fixture_gcode, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    path = first_layers(fixture_gcode, tmp_path, 3, ("M104 S0", "G28 X0"))
    assert (
        main(["print", str(path), "--profile", "paper-prototype", "--resume-from-layer", "2"]) == 1
    )
    assert "not confirmed" in capsys.readouterr().err
