"""`cdprhost check`: exit codes, printed table, JSON fields."""

from __future__ import annotations

import json

from cdprhost.cli.main import main

from .helpers import line_of, square_body, write_program


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_clean_file_exits_0_with_json(tmp_path, capsys):
    path = write_program(tmp_path, square_body())
    report = tmp_path / "out" / "report.json"
    code, out, _ = run(
        capsys, "check", str(path), "--profile", "paper-simulation", "--json", str(report)
    )
    assert code == 0
    assert ": OK" in out.splitlines()[0]
    data = json.loads(report.read_text())
    for key in ("ok", "violations", "moves", "layers", "estimated_time_s", "filament_mm"):
        assert key in data
    assert data["ok"] is True and data["violations"] == [] and data["moves"] == 6
    assert [p.name for p in report.parent.iterdir()] == ["report.json"]  # no temporary left behind


def test_violations_exit_1_smallest_line_printed_first(tmp_path, capsys):
    body = square_body() + ["G1 Z225 F600", "M104 S400"]
    body.insert(3, "G1 X150 Y0 F6000")
    path = write_program(tmp_path, body, start=["M109 S205", "G28", "G92 E0"])
    report = tmp_path / "r.json"
    code, out, _ = run(capsys, "check", str(path), "-p", "paper-prototype", "--json", str(report))
    assert code == 1
    rows = [ln for ln in out.splitlines() if ln.strip()[:1].isdigit()]
    first_bad = line_of(path, "G1 X150 Y0 F6000")
    assert int(rows[0].split()[0]) == first_bad
    data = json.loads(report.read_text())
    assert data["ok"] is False
    lines = [v["line"] for v in data["violations"]]
    assert lines == sorted(lines) and lines[0] == first_bad
    assert set(data["violations"][0]) >= {"line", "rule", "point", "detail"}
    assert {"build_volume", "temperature"} <= {v["rule"] for v in data["violations"]}
    assert line_of(path, "G1 Z225 F600") in lines and line_of(path, "M104 S400") in lines


def test_malformed_gcode_exits_2_naming_line_and_column(tmp_path, capsys):
    body = square_body()
    body.insert(2, "G1 X10 Yabc")
    path = write_program(tmp_path, body)
    code, _, err = run(capsys, "check", str(path), "--profile", "paper-simulation")
    assert code == 2
    assert f"{path}:{line_of(path, 'G1 X10 Yabc')}:8" in err


def test_missing_file_and_bad_profile_exit_2(tmp_path, capsys):
    code, _, err = run(
        capsys, "check", str(tmp_path / "nope.gcode"), "--profile", "paper-simulation"
    )
    assert code == 2 and "nope.gcode" in err
    path = write_program(tmp_path, square_body())
    code, _, err = run(capsys, "check", str(path), "--profile", str(tmp_path / "missing.toml"))
    assert code == 2
