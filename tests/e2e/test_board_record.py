"""`print --port` keeps what the board announced beside the profile, says what it costs,
and `check` estimates for that board afterwards."""

from __future__ import annotations

from cdprhost.cli.main import main
from cdprhost.profile import load_profile
from tests.e2e.processes import SimDeviceProcess, square_part, start_print


def test_a_print_records_the_board_and_check_then_estimates_for_it(tmp_path, monkeypatch, capsys):
    profiles = tmp_path / "profiles"
    monkeypatch.setenv("CDPRHOST_PROFILES", str(profiles))
    part = square_part(tmp_path / "part.gcode", layers=2)
    assert main(["check", str(part), "--profile", "paper-prototype"]) == 0
    assert "board:" not in capsys.readouterr().out
    with SimDeviceProcess(tmp_path, "--speedup", "50", "--max-step-rate", "10000") as dev:
        job = start_print(part, dev.path, tmp_path / "state")
        out, err = job.communicate(timeout=180)
    assert job.returncode == 0, out + err
    assert "(the board's 10,000 steps/s limits module" in out
    sidecar = profiles / "paper-prototype.device.toml"
    assert sidecar.is_file() and not (profiles / "paper-prototype.toml").exists()
    assert load_profile("paper-prototype").device.max_step_rate == 10_000
    assert main(["check", str(part), "--profile", "paper-prototype"]) == 0
    assert "board: the board's 10,000 steps/s limits module" in capsys.readouterr().out
