"""The time estimate: wall-clock, measured machine rate, heating included (pure)."""

from __future__ import annotations

import pytest

from cdprhost.job.state import JobSnapshot, JobState, Temperatures
from cdprhost.tui.control.eta import (
    NOMINAL_C_PER_S,
    estimate,
    heating_rate,
    machine_rate,
)
from cdprhost.tui.control.views import PreflightView, Toolpath
from cdprhost.tui.state import FileView, UiState, job_eta
from cdprhost.tui.widgets.progress_panel import eta_text


def test_machine_rate_from_progress_samples():
    assert machine_rate([], 1.0) == 1.0
    samples = [(100.0 + t, 10.0 * t) for t in range(5)]  # a simulator at 10x
    assert machine_rate(samples, 1.0) == pytest.approx(10.0)
    assert machine_rate(samples[:1], 3.0) == 3.0  # one sample: the default
    old = [(0.0, 0.0)] + [(100.0 + t, 1000.0 + t) for t in range(5)]
    assert machine_rate(old, 1.0) == pytest.approx(1.0)  # only the last 30 s count


def test_heating_rate_only_while_warming():
    assert heating_rate([(0.0, 25.0), (1.0, 28.0), (2.0, 31.0)]) == pytest.approx(3.0)
    assert heating_rate([(0.0, 200.0), (1.0, 200.0), (2.0, 199.0)]) is None
    assert heating_rate([(0.0, 25.0)]) is None


def test_estimate_adds_the_waits_still_ahead():
    waits = [(5, "bed", 60.0), (6, "hotend", 200.0), (900, "hotend", 210.0)]
    at_start = estimate(
        100.0, line=0, temperatures={"hotend": 25.0, "bed": 25.0}, heat_waits=waits, rate=1.0
    )
    expected_heat = 35.0 / NOMINAL_C_PER_S["bed"] + 175.0 / NOMINAL_C_PER_S["hotend"]
    expected_heat += 10.0 / NOMINAL_C_PER_S["hotend"]  # the later wait starts from 200
    assert at_start.heating_left_s == pytest.approx(expected_heat)
    assert at_start.wall_s == pytest.approx(100.0 + expected_heat)
    later = estimate(
        50.0, line=500, temperatures={"hotend": 200.0, "bed": 60.0}, heat_waits=waits, rate=10.0
    )
    assert later.heating_left_s == pytest.approx(10.0 / NOMINAL_C_PER_S["hotend"] / 10.0)
    assert later.wall_s == pytest.approx(5.0 + later.heating_left_s)  # machine time at 10x
    measured = estimate(
        0.0,
        line=0,
        temperatures={"hotend": 100.0, "bed": None},
        heat_waits=[(6, "hotend", 200.0)],
        rate=1.0,
        heating_now={"hotend": 4.0},
    )
    assert measured.heating_left_s == pytest.approx(25.0)


def _toolpath(waits):
    import numpy as np

    z = np.zeros((0, 2), np.float32)
    return Toolpath(
        z, z, np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, bool), (), waits
    )


def test_job_eta_before_and_during_a_print():
    pre = PreflightView(
        "a.gcode", True, (), 10, 2, 600.0, 1.0, (), _toolpath(((3, "hotend", 200.0),))
    )
    idle = UiState(file=FileView("a.gcode", preflight=pre))
    before = job_eta(idle, default_rate=1.0)
    assert before.motion_left_s == 600.0
    assert before.heating_left_s == pytest.approx((200.0 - 25.0) / NOMINAL_C_PER_S["hotend"])
    snap = JobSnapshot(
        state=JobState.PRINTING,
        estimated_time_s=600.0,
        device_time_s=100.0,
        line=10,
        temperatures=Temperatures(200.0, 25.0, 200.0, 0.0),
    )
    running = UiState(
        job=snap,
        job_path="a.gcode",
        file=FileView("a.gcode", preflight=pre),
        rate_samples=((0.0, 0.0), (10.0, 100.0)),
    )
    eta = job_eta(running, default_rate=1.0)
    assert eta.motion_left_s == 500.0 and eta.rate == pytest.approx(10.0)
    assert eta.heating_left_s == 0.0 and eta.wall_s == pytest.approx(50.0)
    text = eta_text(eta, 0.0, JobState.PRINTING).plain
    assert (
        text.startswith("left 0:00:50 wall-clock · done ≈") and "machine time left 0:08:20" in text
    )
