"""A file that fails preflight is refused before anything moves or heats."""

from __future__ import annotations

import json

import pytest

from cdprhost.cli.main import main
from cdprhost.job.runner import PrintJob
from cdprhost.profile import load_profile

GOOD = [
    "G28",
    "M104 S200",
    "M109 S200",
    "G92 E0",
    "G1 Z0.3 F3000",
    ";LAYER_CHANGE",
    "G1 X10 Y0 E1 F1800",
    "G1 X10 Y10 E2",
    "G1 X0 Y10 E3",
    "G1 X0 Y0 E4",
    "M104 S0",
]


def _write(tmp_path, bad_line: str, at: int = 8):
    lines = GOOD[:at] + [bad_line] + GOOD[at:]
    path = tmp_path / "part.gcode"
    path.write_text("\n".join(lines) + "\n")
    return path, at + 1


@pytest.mark.parametrize(
    "bad, rule",
    [
        ("G1 X150 Y0", None),  # outside the build triangle
        ("G1 Z300", None),  # too tall (machine z 410 > 330)
    ],
)
def test_unreachable_moves_are_refused_and_nothing_moves(tmp_path, bad, rule):
    path, line = _write(tmp_path, bad)
    opened = []
    job = PrintJob(path, load_profile("paper-prototype"), lambda: opened.append(1))
    result = job.run()
    assert result.status == "refused" and result.exit_code == 1
    assert result.violations[0]["line"] == line
    assert not opened, "the link must not even be opened"


def test_cli_refuses_malformed_line_naming_it_first(tmp_path, capsys):
    path, line = _write(tmp_path, "G1 X1.2.3")
    report = tmp_path / "r.json"
    code = main(["print", str(path), "--profile", "paper-prototype", "--json", str(report)])
    assert code == 2
    data = json.loads(report.read_text())
    assert data["status"] == "refused" and data["violations"][0]["line"] == line
    assert f":{line}:" in capsys.readouterr().out + data["reason"]


def test_cli_print_small_file_completes(tmp_path):
    path = tmp_path / "ok.gcode"
    path.write_text("\n".join(GOOD) + "\n")
    report = tmp_path / "r.json"
    assert main(["print", str(path), "--profile", "paper-prototype", "--json", str(report)]) == 0
    data = json.loads(report.read_text())
    for key in (
        "status",
        "segments",
        "retransmits",
        "final_steps",
        "last_line",
        "last_layer",
        "print_time_s",
    ):
        assert key in data
    assert data["status"] == "completed" and data["segments"] > 0 and len(data["final_steps"]) == 4
