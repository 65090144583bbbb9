"""``--resume`` rebuilds the interrupted job's program: its placement options are saved in
the resume point and used again; other options are refused with a clear message."""

from __future__ import annotations

import pytest

from cdprhost.cli.main import main
from cdprhost.errors import InputError
from cdprhost.job.resume import ResumePoint, resume_path_for
from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.motion.prepared import Setup
from cdprhost.profile import load_profile
from tests.e2e.processes import square_part
from tests.job.test_job_failsafe import run_job

SHIFTED = Setup(offset=(7.5, -4.0))


@pytest.fixture
def part(tmp_path):
    return square_part(tmp_path / "part.gcode", layers=6)


def test_the_resume_point_keeps_the_setup_and_resume_uses_it(part, tmp_path):
    clean, _ = run_job(part, tmp_path, options=PrintOptions(setup=SHIFTED))
    first, link = run_job(
        part, tmp_path, options=PrintOptions(setup=SHIFTED), faults="reset_after=300"
    )
    assert first.status == "failed" and first.segments == 300
    point = ResumePoint.load(first.resume_file)
    assert point.job_setup() == SHIFTED and point.placement == [7.5, -4.0]
    at_stop = link.device.record[299]
    resumed, link2 = run_job(part, tmp_path, options=PrintOptions(resume=point))  # no options
    assert resumed.status == "completed"
    # it lowers onto the end of the device's last segment: the same physical point
    assert any(r["steps"][:3] == at_stop["steps"][:3] for r in link2.device.record)
    assert resumed.final_steps[:3] == clean.final_steps[:3]


def test_the_same_options_given_again_are_accepted_others_refused(part, tmp_path):
    first, _ = run_job(
        part, tmp_path, options=PrintOptions(setup=SHIFTED), faults="reset_after=300"
    )
    point = ResumePoint.load(first.resume_file)
    profile = load_profile("paper-prototype")
    job = PrintJob(part, profile, lambda: None, PrintOptions(resume=point, setup=SHIFTED))  # type: ignore[arg-type,return-value]
    assert job.setup == SHIFTED
    with pytest.raises(InputError, match="placement options '--offset 7.5,-4'"):
        PrintJob(part, profile, lambda: None, PrintOptions(resume=point, setup=Setup(center=True)))  # type: ignore[arg-type,return-value]


def test_a_point_saved_without_placement_resumes_without_it(part, tmp_path):
    first, link = run_job(part, tmp_path, faults="reset_after=300")
    point = ResumePoint.load(first.resume_file)
    assert point.job_setup() == Setup() and point.placement == [0.0, 0.0]
    with pytest.raises(InputError, match="give the same options or none"):
        PrintJob(
            part,
            load_profile("paper-prototype"),
            lambda: None,
            PrintOptions(resume=point, setup=SHIFTED),
        )  # type: ignore[arg-type,return-value]


def test_cli_resume_with_other_placement_options_is_refused(part, tmp_path, monkeypatch, capsys):
    state = tmp_path / "state"
    monkeypatch.setenv("CDPRHOST_STATE", str(state))
    args = ["print", str(part), "--profile", "paper-prototype", "--center"]
    assert main([*args, "--sim-faults", "reset_after=300"]) == 1
    path = resume_path_for(part, state / "jobs")
    saved = path.read_bytes()
    assert ResumePoint.load(path).job_setup() == Setup(center=True)
    capsys.readouterr()
    code = main(
        ["print", str(part), "--profile", "paper-prototype", "--resume", "--yes", "--offset", "1,2"]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--center" in err and "--offset 1,2" in err and "Traceback" not in err
    assert path.read_bytes() == saved  # nothing happened
    assert main(["print", str(part), "--profile", "paper-prototype", "--resume", "--yes"]) == 0
    assert not path.exists()


def test_a_malformed_saved_setup_is_not_a_resume_point(part, tmp_path):
    first, _ = run_job(
        part, tmp_path, options=PrintOptions(setup=SHIFTED), faults="reset_after=300"
    )
    path = tmp_path / "bad.json"
    text = open(first.resume_file).read().replace('"retarget": false', '"retarget": "yes"')
    path.write_text(text)
    with pytest.raises(InputError, match="center and retarget"):
        ResumePoint.load(path)
