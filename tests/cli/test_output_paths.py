"""A command writes where it is told: ``-`` and ``/dev/stdout`` are standard output (never
a file named ``-``, never a regular file over the ``/dev/stdout`` link), special files are
written in place, a link keeps being a link, new files follow the umask, and a folder or an
unwritable place is one line and exit 2 before any work is reported. Sizes a user can type
are bounded; ``fk`` refuses slider positions outside their travel."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from cdprhost.cli.main import _output_named, main
from cdprhost.fileio.atomic import atomic_open, output_problem, write_text_atomic

POINT = "x,y,z\n0,0,200\n"
HEADER = "x,y,z,s1,s2,s3,n1,n2,n3"


def _ik(tmp_path: Path, out: str) -> int:
    src = tmp_path / "points.csv"
    src.write_text(POINT)
    return main(["ik", "--profile", "paper-simulation", "--in", str(src), "--out", out])


def test_dash_is_stdout_and_no_file_named_dash(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert _ik(tmp_path, "-") == 0
    assert capsys.readouterr().out.startswith(HEADER)
    assert not (tmp_path / "-").exists()


def test_dev_stdout_is_written_as_such_and_stays_a_link(tmp_path):
    src = tmp_path / "points.csv"
    src.write_text(POINT)
    redirected = tmp_path / "redirected.csv"
    with redirected.open("w") as fh:
        inode = os.fstat(fh.fileno()).st_ino
        done = subprocess.run(
            [sys.executable, "-m", "cdprhost", "ik", "--profile", "paper-simulation"]
            + ["--in", str(src), "--out", "/dev/stdout"],
            stdout=fh,
            stderr=subprocess.PIPE,
            text=True,
            timeout=120,
            check=False,
        )
    assert done.returncode == 0, done.stderr
    assert redirected.read_text().startswith(HEADER)
    assert redirected.stat().st_ino == inode  # the shell's file, not a new one renamed over it
    assert os.path.islink("/dev/stdout")


def test_a_fifo_is_written_in_place(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[str] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    write_text_atomic(fifo, "through the pipe\n")
    reader.join(10)
    assert got == ["through the pipe\n"]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_link_stays_a_link_and_its_target_is_replaced(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target.name)
    assert _ik(tmp_path, str(link)) == 0
    assert link.is_symlink()
    assert target.read_text().startswith(HEADER)


@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_new_files_follow_the_umask(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        write_text_atomic(tmp_path / "f.txt", "x\n")
        with atomic_open(tmp_path / "g.bin", "wb") as fh:
            fh.write(b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "f.txt").stat().st_mode) == mode
    assert stat.S_IMODE((tmp_path / "g.bin").stat().st_mode) == mode


def test_a_folder_as_output_is_one_line_and_exit_2_before_any_work(tmp_path, capsys):
    code = main(
        ["calibrate", "plan", "--profile", "paper-simulation", "--out", str(tmp_path), "--poses"]
        + ["4", "--json", str(tmp_path / "r.json")]
    )
    assert code == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing planned, nothing reported
    assert captured.err.strip().count("\n") == 0
    assert "--out" in captured.err and "is a folder" in captured.err
    assert not (tmp_path / "r.json").exists()


def test_check_reports_nothing_done_when_its_json_cannot_be_written(
    tmp_path, capsys, fixture_gcode
):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    code = main(
        ["check", str(fixture_gcode), "--profile", "paper-simulation", "--center"]
        + ["--json", str(blocker / "r.json")]
    )
    assert code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "is not a folder" in captured.err


def test_output_problems_in_a_few_words(tmp_path):
    (tmp_path / "file").write_text("")
    assert output_problem(tmp_path) == "is a folder (a file is needed here)"
    assert output_problem(tmp_path / "new" / "deeper" / "x.csv") is None  # folders are made
    assert "is not a folder" in str(output_problem(tmp_path / "file" / "x.csv"))
    assert output_problem(tmp_path / "file", folder=True) == "exists and is not a folder"
    assert output_problem("-") is None
    assert output_problem("-", folder=True) is not None


def test_an_oserror_while_writing_an_output_is_recognised(tmp_path):
    out = str(tmp_path / "r.json")
    tmp = OSError(28, "No space left on device", str(tmp_path / ".r.json.abc123.tmp"))
    assert _output_named(tmp, [out]) == out
    assert _output_named(OSError(5, "I/O error", "/dev/ttyACM0"), [out]) is None


def test_fk_refuses_sliders_outside_their_travel(tmp_path, capsys):
    src = tmp_path / "sliders.csv"
    src.write_text("s1,s2,s3\n-68,-65,-64\n0,5000,0\n")
    out = tmp_path / "points.csv"
    assert main(["fk", "--profile", "paper-simulation", "--in", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "row 3: s2 = 5000 mm is outside its travel" in err
    assert not out.exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["calibrate", "camera", "--camera", "sim", "--sim-camera", "100000x100000"],
        ["calibrate", "camera", "--camera", "sim", "--sim-camera", "8000x6000"],
        ["calibrate", "camera", "--camera", "sim", "--views", "100000"],
        ["calibrate", "plan", "--profile", "paper-simulation", "--poses", "1000000000"],
        ["calibrate", "plan", "--profile", "paper-simulation", "--seed", "-1"],
        ["calibrate", "boards", "--png-dpi", "100000"],
        ["diagnose", "s", "--profile", "paper-simulation", "--folds", "100000"],
    ],
)
def test_sizes_a_user_types_are_bounded(argv, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert any(word in err for word in ("outside", "at most", "must be"))


def test_json_to_stdout_is_the_only_thing_on_stdout(capsys):
    example = Path(__file__).resolve().parents[2] / "examples" / "example.gcode"
    assert main(["check", str(example), "--profile", "paper-prototype", "--json", "-"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # nothing but the report: `--json - | jq` works
    assert report["ok"] is True
    assert captured.err.strip()  # the human report went to stderr


def test_a_regular_file_under_dev_is_still_replaced_whole(tmp_path):
    """Only names of open files (/dev/stderr, /dev/fd/N, /proc/...) are written in place."""
    from cdprhost.fileio.atomic import is_special

    assert is_special("/dev/stderr") and is_special("/dev/fd/2") and is_special("/dev/null")
    assert not is_special("/dev/shm/cdprhost-report.json")
    assert not is_special(tmp_path / "report.json")
