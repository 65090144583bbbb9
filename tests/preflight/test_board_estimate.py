"""The estimate is for the board the profile drives: its announced step rate, from the
profile's ``[device]`` record before connecting and from the device once connected; a
board that slows the print is named with the factor."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import Planned
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.device_limits import AXES, busiest_axis
from cdprhost.preflight.run import preflight
from cdprhost.profile import DeviceRecord, load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from tests.e2e.processes import square_part

#: the AVR firmware's announcement: 10,000 steps/s, 40 ticks of 10 us
AVR = DeviceRecord(max_step_rate=10_000, min_segment_s=400e-6)


def _on(profile, record):
    return profile.model_copy(update={"device": record})


def test_a_slow_board_lengthens_the_estimate_and_is_named_with_the_factor(fixture_gcode):
    profile = load_profile("paper-prototype")
    free = preflight(fixture_gcode, profile)
    board = preflight(fixture_gcode, _on(profile, AVR))
    assert free.board is None
    assert board.estimated_time_s > 1.05 * free.estimated_time_s
    b = board.board
    assert b is not None and b.source == "profile" and b.max_step_rate == 10_000
    assert b.time_at_profile_limits_s == pytest.approx(free.estimated_time_s)
    pct = round(100 * (board.estimated_time_s / free.estimated_time_s - 1))
    assert "the board's 10,000 steps/s limits module" in b.message
    assert f"+{pct} %" in b.message
    assert sum(b.slowed_axes.values()) <= 1.0 + 1e-6 and b.slowed_axes
    assert set(b.slowed_axes) <= set(AXES)
    # the checks themselves do not change
    assert board.violations_total == free.violations_total and board.moves == free.moves


def test_a_fast_board_changes_nothing_and_says_so(fixture_gcode):
    profile = load_profile("paper-prototype")
    free = preflight(fixture_gcode, profile)
    fast = preflight(fixture_gcode, _on(profile, DeviceRecord(max_step_rate=1_000_000)))
    assert fast.estimated_time_s == free.estimated_time_s
    assert fast.board is not None and fast.board.message == ""


def test_the_busiest_axis_is_the_cable_the_move_runs_along():
    model = MachineModel.from_profile(load_profile("paper-prototype"))
    outlets = model.geometry.outlets
    mid = np.array([0.0, 0.0, 200.0])
    spm = np.array([400.0, 400.0, 400.0])
    for k in range(3):
        along = (mid - outlets[k]) / np.linalg.norm(mid - outlets[k])
        start, end = mid[None, :], (mid + 5.0 * along)[None, :]
        assert busiest_axis(start, end, np.zeros(1), outlets, spm, 95.5)[0] == k
    # an extrude-only move, and a slow move that feeds a lot of filament
    assert busiest_axis(mid[None], mid[None], np.ones(1), outlets, spm, 95.5)[0] == 3
    end = (mid + [0.01, 0, 0])[None]
    assert busiest_axis(mid[None], end, np.ones(1), outlets, spm, 95.5)[0] == 3


def _print(tmp_path, profile, announced, **options):
    path = square_part(tmp_path / "part.gcode", layers=3)
    # without G28: homing takes the device 2 s from where its carriages boot, a time no
    # estimate made before connecting can know
    path.write_text(path.read_text().replace("G28\n", "", 1))
    events = []
    cfg = SimConfig(max_step_rate=announced.max_step_rate, min_segment_ticks=40)
    job = PrintJob(
        path,
        profile,
        lambda: open_embedded(config=cfg),
        PrintOptions(log_path=tmp_path / "job.jsonl", resume_dir=tmp_path, **options),
        on_event=events.append,
    )
    result = job.run()
    assert result.status == "completed", result.reason
    return result, [e for e in events if isinstance(e, Planned)]


def test_the_estimate_on_the_recorded_board_is_within_1_percent_of_the_print(tmp_path):
    result, planned = _print(tmp_path, _on(load_profile("paper-prototype"), AVR), AVR)
    assert len(planned) == 1  # the record was right: no second estimate
    assert result.estimated_time_s == pytest.approx(result.print_time_s, rel=0.01)
    assert result.board.startswith("the board's 10,000 steps/s limits module")
    assert result.board in result.notices


def test_once_connected_the_estimate_follows_the_board_and_is_recorded(tmp_path):
    kept = []
    result, planned = _print(
        tmp_path, load_profile("paper-prototype"), AVR, record_device=kept.append
    )
    assert len(planned) == 2  # before connecting (no record), then on the board's limits
    assert planned[0].estimated_time_s < 0.95 * result.print_time_s
    assert planned[1].estimated_time_s == pytest.approx(result.print_time_s, rel=0.01)
    assert result.estimated_time_s == planned[1].estimated_time_s
    assert "the board's 10,000 steps/s limits" in result.board
    assert [r.same_limits(AVR) for r in kept] == [True]


def test_check_says_what_the_recorded_board_costs(tmp_path, monkeypatch, capsys, fixture_gcode):
    import json

    from cdprhost.cli.main import main
    from cdprhost.profile import record_device

    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path / "profiles"))
    report = tmp_path / "report.json"
    args = ["check", str(fixture_gcode), "--profile", "paper-prototype", "--json", str(report)]
    assert main(args) == 0
    free = json.loads(report.read_text())
    assert "board:" not in capsys.readouterr().out and free["board"] is None
    record_device("paper-prototype", AVR)  # as a print on the AVR leaves it
    assert main(args) == 0
    out = capsys.readouterr().out
    data = json.loads(report.read_text())
    pct = round(100 * (data["estimated_time_s"] / free["estimated_time_s"] - 1))
    assert pct >= 5 and data["board"]["max_step_rate"] == 10_000
    line = next(t for t in out.splitlines() if t.startswith("board: "))
    assert "the board's 10,000 steps/s limits module" in line and f"+{pct} %" in line
    assert "the profile's [device] record" in line


def test_the_tui_estimates_for_the_connected_board(tmp_path):
    from cdprhost.tui.control.live import EMBEDDED, LiveBackend

    path = square_part(tmp_path / "part.gcode", layers=2)
    cfg = SimConfig(max_step_rate=AVR.max_step_rate, min_segment_ticks=40)
    backend = LiveBackend("paper-prototype", speedup=None, sim_options={"config": cfg})
    free = backend.preflight(str(path)).estimated_time_s  # not connected: the profile's limits
    backend.connect(EMBEDDED, 250_000)
    try:
        board = backend.preflight(str(path)).estimated_time_s
    finally:
        backend.disconnect()
    slowed = preflight(path, _on(load_profile("paper-prototype"), AVR)).estimated_time_s
    assert board == pytest.approx(slowed) and board > 1.05 * free
