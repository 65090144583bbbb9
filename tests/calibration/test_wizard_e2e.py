"""The calibration wizard end to end against the embedded simulated device with a
hidden true machine and virtual motion capture; then printing with the result."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cdprhost.calibration.wizard import CalibrationWizard, FolderWatcher, WizardOptions
from cdprhost.cli.main import main
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.machine import Machine
from cdprhost.motion.limits import Caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.planner import Planner
from cdprhost.motion.segments import Segmenter
from cdprhost.profile import load_profile, save_profile
from cdprhost.sim.embedded import open_embedded
from cdprhost.sim.measurement import achieved_points
from cdprhost.sim.virtual_mocap import make_observer, mocap_config
from firmware_protocol.ramp_profile import ramp_codes_from_speeds
from firmware_protocol.segments import SegmentBatch

from .conftest import paper_truth_geometry


@pytest.fixture()
def truth_path(sim_profile, tmp_path):
    g = paper_truth_geometry()
    path = tmp_path / "truth.toml"
    save_profile(sim_profile.with_geometry(g.outlets, g.initial_lengths, name="hidden-truth"), path)
    return path


def embedded(truth_path, mocap_dir):
    observer = make_observer(truth_path, mocap_dir)
    link = open_embedded(observer=observer)
    observer.attach_record(link.device.record)
    return link


def print_path_errors(profile, truth: MachineModel, path: np.ndarray) -> np.ndarray:
    """Stream ``path`` to the embedded device commanded with ``profile``; distance between
    each commanded segment end and where the true machine's recorded steps put it."""
    model = MachineModel.from_profile(profile)
    link = open_embedded()
    try:
        dev = Machine(link, profile, model, settle_s=0.5)
        dev.home()
        planner = Planner(
            Caps.from_profile(profile.motion, profile.extruder, profile.statics.a_max_mm_s2),
            model.geometry.outlets,
        )
        seg = Segmenter(
            model,
            profile.drive.home_mm,
            e_steps_per_mm=profile.extruder.steps_per_mm,
            clock_hz=link.identity.clock_hz,
        )
        start = np.vstack([model.home_point(np.zeros(3))[None], path[:-1]])
        points, sent = [], 0
        for planned in (
            planner.push(MoveBlock.from_arrays(start, path, feedrate=60.0)) + planner.flush()
        ):
            b = seg(planned)
            link.queue_segments(
                SegmentBatch(b.ticks, b.delta, ramp_codes_from_speeds(b.v_start, b.v_end))
            )
            points.append(b.point)
            sent += len(b)
        link.wait_idle(120)
        record = link.device.record[-sent:]
    finally:
        link.close()
    steps = np.array([r["steps"][:3] for r in record], dtype=float)
    achieved = truth.fk(truth.sliders_from_steps(steps))
    return np.linalg.norm(achieved - np.vstack(points), axis=1)


def test_wizard_calibrates_then_printing_gets_accurate(
    sim_profile, sim_model, truth_path, tmp_path
):
    truth = MachineModel.from_profile(load_profile(truth_path))
    link = embedded(truth_path, tmp_path / "mocap")
    logs: list[str] = []
    try:
        wiz = CalibrationWizard(
            tmp_path / "session",
            sim_profile,
            Machine(link, sim_profile, sim_model, settle_s=0.5),
            FolderWatcher(tmp_path / "mocap", timeout_s=5, poll_s=0.01),
            mocap=mocap_config().mocap,
            options=WizardOptions(n_poses=4),
            log=logs.append,
        )
        out = wiz.run()
    finally:
        link.close()
    r = out.identification
    # 4 fit poses verified on 3 check poses, then refined on all 7
    assert r.ok and r.poses_used == 7 and r.verification is not None
    assert r.verification.consistent and r.verification.refined and len(r.verification.checks) == 3
    assert r.rms_before_mm > 5.0 and r.rms_after_mm < 0.05 and r.dof == 9
    assert r.check_rms_before_mm > 2.0 and r.check_rms_after_mm < 0.5
    assert (tmp_path / "session" / "calibrated.toml").is_file() and (
        tmp_path / "session" / "identification.json"
    ).is_file()
    cal = load_profile(out.profile_path)
    cal_model = MachineModel.from_profile(cal)

    grid = workspace_grid(sim_model)
    before = np.linalg.norm(achieved_points(truth, sim_model, grid) - grid, axis=1)
    after = np.linalg.norm(achieved_points(truth, cal_model, grid) - grid, axis=1)
    assert np.sqrt(np.mean(before**2)) > 5.0 and np.sqrt(np.mean(after**2)) < 0.3

    t = np.linspace(0, 2 * np.pi, 40)
    path = np.vstack(
        [
            np.column_stack([25 * np.cos(t), 25 * np.sin(t), np.full(t.size, z)])
            for z in (140.0, 220.0)
        ]
    )
    err_nominal = print_path_errors(sim_profile, truth, path)
    err_calibrated = print_path_errors(cal, truth, path)
    assert np.sqrt(np.mean(err_nominal**2)) > 5.0
    assert np.sqrt(np.mean(err_calibrated**2)) < 0.3
    assert any("recorded pose 7/7" in m for m in logs)


class InterruptAfter:
    """A take source that stops the session (like Ctrl-C) when asked for take ``n``."""

    def __init__(self, inner, n):
        self.inner, self.n, self.calls = inner, n, 0

    def take_for(self, index, pose, attempt):
        self.calls += 1
        if self.calls == self.n:
            raise KeyboardInterrupt
        return self.inner.take_for(index, pose, attempt)


def test_interrupted_session_resumes_without_losing_takes(
    sim_profile, sim_model, truth_path, tmp_path
):
    session, mocap = tmp_path / "session", tmp_path / "mocap"
    link = embedded(truth_path, mocap)
    try:
        takes = InterruptAfter(FolderWatcher(mocap, timeout_s=5, poll_s=0.01), 4)
        wiz = CalibrationWizard(
            session,
            sim_profile,
            Machine(link, sim_profile, sim_model, settle_s=0.5),
            takes,
            mocap=mocap_config().mocap,
            options=WizardOptions(n_poses=4),
            log=lambda m: None,
        )
        with pytest.raises(KeyboardInterrupt):
            wiz.run()
    finally:
        link.close()
    rows = list(csv.DictReader(open(session / "poses.csv")))
    assert [r["plan_pose"] for r in rows] == ["1", "2", "3"]
    first_rows = (session / "poses.csv").read_text()

    link = embedded(truth_path, mocap)  # a new device (power cycle): homes again
    try:
        wiz = CalibrationWizard(
            session,
            sim_profile,
            Machine(link, sim_profile, sim_model, settle_s=0.5),
            FolderWatcher(mocap, timeout_s=5, poll_s=0.01),
            mocap=None,
            options=WizardOptions(n_poses=4),
            log=lambda m: None,
        )
        assert wiz.state.pending == [3, 4, 5, 6]
        out = wiz.run()
    finally:
        link.close()
    text = (session / "poses.csv").read_text()
    assert text.startswith(first_rows)
    rows = list(csv.DictReader(open(session / "poses.csv")))
    assert [r["plan_pose"] for r in rows] == [str(i) for i in range(1, 8)]
    assert [r["pose"] for r in rows] == [str(i) for i in range(1, 8)]
    assert out.identification.ok and out.identification.check_rms_after_mm < 0.5


class WrongThenRight:
    """First offers a take of another pose, then the right one."""

    def __init__(self, inner, wrong):
        self.inner, self.wrong, self.given = inner, wrong, set()

    def take_for(self, index, pose, attempt):
        if index == 1 and attempt == 1:
            return self.wrong
        return self.inner.take_for(index, pose, attempt)


def test_wrong_take_is_rejected_at_once_and_asked_again(
    sim_profile, sim_model, truth_path, tmp_path
):
    mocap = tmp_path / "mocap"
    link = embedded(truth_path, mocap)
    logs: list[str] = []
    try:
        watcher = FolderWatcher(mocap, timeout_s=5, poll_s=0.01)
        source = WrongThenRight(watcher, mocap / "take-0001.csv")
        wiz = CalibrationWizard(
            tmp_path / "s",
            sim_profile,
            Machine(link, sim_profile, sim_model, settle_s=0.5),
            source,
            mocap=mocap_config().mocap,
            options=WizardOptions(n_poses=4, n_check=1),
            log=logs.append,
        )
        out = wiz.run()
    finally:
        link.close()
    assert any("take refused (wrong-pose" in m and "from the commanded pose" in m for m in logs)
    rows = list(csv.DictReader(open(tmp_path / "s" / "poses.csv")))
    assert len(rows) == 5 and out.identification.ok


def test_wizard_cli_end_to_end(truth_path, tmp_path, capsys):
    report = tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "wizard",
            "--profile",
            "paper-simulation",
            "--session",
            str(tmp_path / "s"),
            "--sim-truth",
            str(truth_path),
            "--sim-mocap-dir",
            str(tmp_path / "mocap"),
            "--out",
            str(tmp_path / "cal.toml"),
            "--json",
            str(report),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "before/after" in out and "check poses RMS" in out
    data = json.loads(report.read_text())
    assert data["poses_used"] == 7 and data["ok"] is True  # 4 fit + 3 check, verified, refined
    assert data["verification"]["verdict"] == "consistent" and data["verification"]["refined"]
    assert "verification of the fit poses on 3 check pose(s): CONSISTENT" in out
    assert data["rms_after_mm"] < 0.05 and data["predicted_workspace_max_mm"] < 0.3
    assert load_profile(tmp_path / "cal.toml").calibration["poses_used"] == 7

    # the same takes, recorded beforehand, through --takes-from (no virtual mocap this time)
    code = main(
        [
            "calibrate",
            "wizard",
            "--profile",
            "paper-simulation",
            "--session",
            str(tmp_path / "again"),
            "--takes-from",
            str(tmp_path / "s" / "takes"),
            "--mocap-config",
            str(tmp_path / "s" / "session.toml"),
            "--json",
            str(tmp_path / "again.json"),
        ]
    )
    assert code == 0
    again = json.loads((tmp_path / "again.json").read_text())
    np.testing.assert_allclose(
        again["parameters"]["outlets"], data["parameters"]["outlets"], atol=1e-6
    )
    capsys.readouterr()
    code = main(
        [
            "calibrate",
            "wizard",
            "--profile",
            "paper-simulation",
            "--session",
            str(tmp_path / "t"),
            "--sim-mocap-dir",
            str(tmp_path / "m2"),
        ]
    )
    err = capsys.readouterr().err
    # the wizard's own flags, not sim-device's --truth / --mocap-dir
    assert code == 2 and "--sim-mocap-dir needs --sim-truth" in err and " --truth" not in err
