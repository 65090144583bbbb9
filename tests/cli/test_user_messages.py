"""What a new user reads: one wording for a missing file, a refusal said once, where a print
ran and its job log, the wizard's own flags, how to get the poses a diagnosis needs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from cdprhost.job.resume import log_path_for

ROOT = Path(__file__).resolve().parents[2]
CUBE = ROOT / "tests" / "gcode" / "data" / "thirdparty" / "cura413_ender3_cube.gcode"


def cli(*args: str, state: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    if state is not None:
        env["XDG_STATE_HOME"] = str(state)
    return subprocess.run(
        [sys.executable, "-m", "cdprhost", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )


def test_print_and_check_word_a_missing_file_the_same(tmp_path):
    missing = str(tmp_path / "nope.gcode")
    errors = []
    for command in ("check", "print"):
        run = cli(command, missing, "--profile", "paper-prototype")
        assert run.returncode == 2
        errors.append(run.stderr.split("error: ", 1)[1].strip())
    assert errors[0] == errors[1] == f"{missing}: G-code file not found"


def test_a_refused_print_names_its_first_violation_once(tmp_path):
    run = cli("print", str(CUBE), "--profile", "paper-prototype", state=tmp_path)
    assert run.returncode == 1
    out = run.stdout + run.stderr
    first = next(ln for ln in run.stdout.splitlines() if ln.startswith("  line "))
    assert out.count(first.strip()) == 1, out
    assert "nothing moved" in run.stdout and "--retarget" in run.stdout


def test_a_print_says_where_it_ran_its_log_and_the_final_steps(tmp_path):
    state = tmp_path / "new-state"  # does not exist yet
    gcode = tmp_path / "tiny.gcode"
    gcode.write_text("G28\nG1 Z5 F600\nG1 X5 Y5 Z5 F3000\n")
    run = cli("print", str(gcode), "--profile", "paper-prototype", state=state)
    assert run.returncode == 0, run.stderr
    assert "ran on the embedded simulated device (no --port: nothing physical moved)" in run.stdout
    assert "final steps: the device's absolute step counters" in run.stdout
    log = next(ln for ln in run.stdout.splitlines() if ln.startswith("job log: "))
    jsonl = Path(log.split("job log: ")[1].split(" (")[0])
    assert jsonl.is_file() and jsonl.with_suffix(".log").is_file()  # the first print writes both


def test_two_prints_in_the_same_second_get_two_log_names(tmp_path):
    first = log_path_for("part.gcode", tmp_path)
    first.write_text("")
    second = log_path_for("part.gcode", tmp_path)
    assert second != first and second.name.startswith("part-")
    second.with_suffix(".log").write_text("")  # a .log alone also takes the name
    assert log_path_for("part.gcode", tmp_path) not in (first, second)


def test_the_wizard_names_its_own_flags(tmp_path):
    run = cli(
        "calibrate", "wizard", "--profile", "paper-simulation", "--session", str(tmp_path / "s")
    )
    assert run.returncode == 2
    assert (
        "--mocap-config" in run.stderr and "--sim-truth PROFILE --sim-mocap-dir DIR" in run.stderr
    )
    run = cli(
        "calibrate", "wizard", "--profile", "paper-simulation", "--session", str(tmp_path / "s"),
        "--sim-truth", "paper-prototype",
    )  # fmt: skip
    assert run.returncode == 2 and "--sim-truth needs --sim-mocap-dir" in run.stderr


def test_a_simulated_truth_numbered_otherwise_is_refused_before_any_take(tmp_path):
    run = cli(
        "calibrate", "wizard", "--profile", "paper-simulation", "--session", str(tmp_path / "s"),
        "--sim-truth", "paper-prototype", "--sim-mocap-dir", str(tmp_path / "m"),
    )  # fmt: skip
    assert run.returncode == 2
    assert "the profile's modules 1, 2, 3 are its modules 2, 1, 3" in run.stderr
    assert not (tmp_path / "m").exists() or not any((tmp_path / "m").iterdir())  # no take


def test_diagnose_on_a_wizard_sized_session_says_how_to_get_enough_poses(tmp_path):
    demo = tmp_path / "demo"
    run = cli("calibrate", "demo", "--profile", "paper-simulation", "--out", str(demo))
    assert run.returncode == 0, run.stderr
    assert (demo / "hidden-truth.toml").is_file() and "hidden machine" in run.stdout
    run = cli("calibrate", "demo", "--profile", "paper-simulation", "--out", str(demo))
    assert run.returncode == 2 and "not empty" in run.stderr
    # keep 7 poses, as the wizard's default session has
    small = tmp_path / "small"
    shutil.copytree(demo, small)
    lines = (small / "poses.csv").read_text().splitlines()
    (small / "poses.csv").write_text("\n".join(lines[:8]) + "\n")
    run = cli("diagnose", str(small), "--profile", "paper-simulation")
    assert run.returncode == 2
    assert "at least 8 measured poses, got 7" in run.stderr and "--poses 12" in run.stderr
    assert "cdprhost calibrate demo" in run.stderr


@pytest.mark.skipif(shutil.which("simavr") is None and not Path("/usr/include/simavr").exists(),
                    reason="needs simavr")  # fmt: skip
def test_sim_device_avr_prints_its_pty_path_first_and_no_loader_chatter(tmp_path):
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", "avr"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().startswith("/dev/")
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=60)
    assert "Loaded" not in err


def test_the_print_summary_names_a_host_that_came_late_to_refill(capsys):
    """A busy PC that made the host keep more motion ahead is named in the summary with
    what it cost (pauses and speed changes later); a prompt one is not mentioned."""
    import argparse

    from cdprhost.cli.commands.print_cmd import _report
    from cdprhost.job.options import PrintResult

    args = argparse.Namespace(port=None, json=None)
    late = PrintResult("completed", segments=10, host_late_s=0.42, lead_s=1.26)
    _report(late, args, None)
    said = capsys.readouterr().out
    assert "0.42 s late to refill the device" in said and "1.3 s of motion ahead" in said
    _report(PrintResult("completed", segments=10, host_late_s=0.02, lead_s=0.5), args, None)
    assert "late to refill" not in capsys.readouterr().out
