"""Pure pieces of the UI: text charts, source index, jog feasibility, state folding, the event pump."""

from __future__ import annotations

import threading

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.job.state import (
    Failure,
    JobSnapshot,
    JobState,
    Planned,
    Progress,
    StateChanged,
)
from cdprhost.tui.control.jog import check_jog, jog_target
from cdprhost.tui.control.pump import EventPump
from cdprhost.tui.control.source import SourceLines
from cdprhost.tui.control.views import PreflightView, ViolationRow
from cdprhost.tui.screens.dialogs import failure_text
from cdprhost.tui.screens.print_screen import preflight_summary
from cdprhost.tui.state import FileView, UiState, fold_job_events, hms
from cdprhost.tui.widgets.charts import BLOCKS, block_chart, hbar, tension_level
from cdprhost.tui.widgets.gap_plot import AFTER, BEFORE, FLOOR, gap_cells
from cdprhost.tui.widgets.progress_panel import progress_lines


def filled_eighths(rows: list[str]) -> np.ndarray:
    """Per column, how many eighths of the chart are filled."""
    width = len(rows[0])
    total = np.zeros(width, dtype=int)
    for row in rows:
        total += np.array([BLOCKS.index(c) if c in BLOCKS else 0 for c in row])
    return total


@given(st.lists(st.floats(0, 300), min_size=1, max_size=120), st.integers(1, 60), st.integers(1, 6))
def test_block_chart_shape_and_monotone(values, width, height):
    rows = block_chart(values, width, height, 0.0, 300.0)
    assert len(rows) == height and all(len(r) == width for r in rows)
    shown = values[-width:]
    fill = filled_eighths(rows)[width - len(shown) :]
    order = np.argsort(shown, kind="stable")
    assert np.all(np.diff(fill[order]) >= 0)  # a larger value never draws a shorter column
    assert np.all(np.abs(fill - np.asarray(shown) / 300.0 * height * 8) <= 0.5 + 1e-9)


def test_block_chart_marker_and_right_alignment():
    rows = block_chart([150.0, 150.0], 6, 2, 0.0, 200.0, marker=150.0)
    assert (
        rows[0] == "┈┈┈┈▄▄"
    )  # target line in the empty cells of the top row, newest values on the right
    assert rows[1] == "    ██"


@given(st.floats(-10, 400), st.integers(1, 50))
def test_hbar_width_and_fill(value, width):
    bar = hbar(value, 300.0, width)
    assert len(bar) == width
    frac = min(max(value / 300.0, 0.0), 1.0)
    assert bar.count("█") == int(round(frac * width * 8)) // 8


def test_tension_levels():
    assert tension_level(1.0, 2.0, 300.0) == "bad"
    assert tension_level(301.0, 2.0, 300.0) == "bad"
    assert tension_level(float("nan"), 2.0, 300.0) == "bad"
    assert tension_level(3.0, 2.0, 300.0) == "near"
    assert tension_level(290.0, 2.0, 300.0) == "near"
    assert tension_level(50.0, 2.0, 300.0) == "ok"


def test_gap_cells_after_below_before_and_floor_line():
    rows, top, floor_at = gap_cells([0.3, 0.2, 0.1], [0.05, 0.05, 0.05], 0.06, 40, 4)
    assert top > 0.3 and len(rows) == 4 and all(len(r) == 3 for r in rows)
    bottom = rows[-1]
    assert all(style == AFTER for _, style in bottom)  # the after part sits at the bottom
    assert rows[0][0][1] == BEFORE  # the tallest 'before' column reaches the top row
    assert floor_at == 3  # 0.06 mm of 0.33 mm falls in the bottom row
    rows, _, floor_at = gap_cells([0.3, 0.1], [0.05, 0.05], 0.2, 40, 4)
    assert floor_at == 1 and rows[1][1] == ("┈", FLOOR)  # above the short bar the floor line shows


@given(
    st.lists(st.text(alphabet="G1XYZ0123456789 .;-é", max_size=12), min_size=1, max_size=40),
    st.booleans(),
)
def test_source_lines_match_splitlines(tmp_path_factory, lines, trailing_newline):
    path = tmp_path_factory.mktemp("src") / "f.gcode"
    text = "\n".join(lines) + ("\n" if trailing_newline else "")
    path.write_text(text, encoding="utf-8")
    src = SourceLines(path)
    expected = text.splitlines()
    assert len(src) == len(expected)
    for i, line in enumerate(expected, start=1):
        assert src.line(i) == line
    assert src.line(0) == "" and src.line(len(expected) + 1) == ""
    around = src.around(1, 2, 2)
    assert [n for n, _ in around] == list(range(1, min(3, len(expected)) + 1))


def test_jog_feasibility(sim_model):
    start = (0.0, 0.0, 200.0)
    ok = check_jog(sim_model, start, jog_target(start, "x", 10.0))
    assert ok.ok and ok.target == (10.0, 0.0, 200.0)
    low = check_jog(sim_model, start, jog_target(start, "z", -95.0))  # below z_min = 110
    assert not low.ok and not low.target_ok
    assert low.reason == "target: build_volume: outside the build volume by 5 mm"
    far = check_jog(sim_model, start, jog_target(start, "y", -200.0))
    assert not far.ok and far.reason.startswith("target: ")
    assert check_jog(sim_model, None, (0.0, 0.0, 200.0)).ok  # unknown start: the target alone


def test_fold_ignores_other_jobs_and_reports_illegal_transitions():
    state = UiState(job_id=2)
    items = [
        (1, StateChanged(JobState.PREFLIGHT)),
        (2, StateChanged(JobState.PREFLIGHT)),
        (2, Planned(3, 10, 5.0, 1.0, 10)),
        (2, StateChanged(JobState.DONE)),  # illegal from preflight
        (2, StateChanged(JobState.PRINTING)),
        (2, Progress(4, 20, 1, 2.0)),
    ]
    new, problems = fold_job_events(state, items)
    assert new.job.state is JobState.PRINTING and new.job.segments_done == 4 and new.job.layers == 3
    assert problems == ["preflight -> done is not allowed"]
    same, none = fold_job_events(new, [(1, Progress(9, 9, 9, 9.0))])
    assert same is new and none == []


def test_event_pump_wakes_once_per_burst_and_keeps_order():
    wakes = []
    pump = EventPump(lambda: wakes.append(1))
    n_threads, per_thread = 4, 500

    def worker(k):
        for i in range(per_thread):
            pump.put(k, i)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    items = pump.drain()
    assert len(items) == n_threads * per_thread
    for k in range(n_threads):
        assert [i for j, i in items if j == k] == list(range(per_thread))
    assert len(wakes) == 1  # nobody drained in between: one wake-up for the whole burst
    pump.put(0, "again")
    assert len(wakes) == 2 and pump.drain() == [(0, "again")]


def test_progress_lines_layers_eta_and_line():
    snap = JobSnapshot(
        state=JobState.PRINTING,
        layers=12,
        layer=4,
        segments_total=100,
        segments_done=25,
        estimated_time_s=400.0,
        device_time_s=100.0,
        line=42,
    )
    head, stats, line = progress_lines(snap, "G1 X1 Y2", elapsed_s=130.0)
    assert "PRINTING" in head.plain
    assert stats.plain == "layer 5/12 · elapsed 0:02:10 · machine 0:01:40"  # wall vs machine
    assert line.plain == "line 42: G1 X1 Y2"
    assert hms(3725) == "1:02:05" and hms(None) == "--:--:--"
    head, _, _ = progress_lines(snap, "", shown=JobState.PAUSING)
    assert "PAUSING" in head.plain and "stopping within the moves sent" in head.plain


def test_failure_text_names_stop_and_resume_point():
    f = Failure("device reset", 1234, 7, (1.0, 2.0, 3.0), "/x/part.resume.json")
    text = failure_text(f, "", "G1 X5", "part.gcode").plain
    assert "reason: device reset" in text and "last executed line: 1234  G1 X5" in text
    assert "last layer: 8 (index 7)" in text and "/x/part.resume.json" in text
    assert "cdprhost print part.gcode --resume-from-layer 8" in text


def test_preflight_summary_names_first_violation():
    view = PreflightView(
        "a.gcode",
        False,
        (ViolationRow(40, "tension", "x"), ViolationRow(12, "build_volume", "y")),
        5,
        1,
        65.0,
        2.0,
    )
    text = preflight_summary(UiState(file=FileView(path="a.gcode", preflight=view))).plain
    assert text.startswith("2 violations (first at line 12)") and "machine time 0:01:05" in text
    assert "o Open picks one" in preflight_summary(UiState(), "o Open").plain


def test_calibration_result_shows_the_trust_gate_verdict():
    from cdprhost.tui.control.views import IdentificationView
    from cdprhost.tui.screens.calibrate import result_text

    base = IdentificationView((), 14.2, 0.05, 5, 12)
    assert "trust gate: not run" in result_text(base).plain
    trusted = IdentificationView(
        (),
        14.2,
        0.05,
        5,
        12,
        trusted=True,
        predicted_rms_mm=0.021,
        predicted_max_mm=0.05,
        profile_path="/s/calibrated.toml",
    )
    text = result_text(trusted).plain
    assert "trust gate: trusted" in text and "0.021 mm RMS, 0.050 mm max" in text
    assert "profile written: /s/calibrated.toml" in text
    refused = IdentificationView(
        (),
        14.2,
        0.05,
        5,
        12,
        warnings=("predicted error 0.9 mm",),
        trusted=False,
        predicted_rms_mm=0.9,
        predicted_max_mm=2.0,
    )
    text = result_text(refused).plain
    assert "trust gate: REFUSED: no profile written" in text and "! predicted error 0.9" in text
    assert "profile written" not in text.replace("no profile written", "")


def test_event_pump_wakes_again_for_an_urgent_event():
    wakes = []
    pump = EventPump(lambda: wakes.append(1), urgent=lambda e: e == "state")
    pump.put(1, "progress")
    pump.put(1, "progress")
    assert len(wakes) == 1 and not pump.urgent  # progress waits for the next fold
    pump.put(1, "state")
    assert len(wakes) == 2 and pump.urgent  # a state change is shown at once
    pump.put(1, "state")
    assert len(wakes) == 2
    assert [e for _, e in pump.drain()] == ["progress", "progress", "state", "state"]
    assert not pump.urgent


def test_position_numbers_never_run_together():
    from cdprhost.tui.widgets.position_panel import position_rows

    text = position_rows((-150.25, -1200.5, 330.0), (-100.125, -250.5, -1000.25), (1, 2, 3, 4))
    rows = text.plain.split("\n")
    assert rows[0].split()[1:4] == ["-150.25", "-1200.50", "330.00"]  # machine frame, labelled
    assert rows[2].split()[1:4] == ["-100.125", "-250.500", "-1000.250"]


def test_a_source_line_too_wide_loses_its_comment_before_its_code():
    from cdprhost.tui.widgets.source_view import fit_line

    assert fit_line("G1 X1 Y2", 20) == "G1 X1 Y2"
    assert fit_line("G1 X15.00 Y-15.00 E4.5 ; perimeter", 26) == "G1 X15.00 Y-15.00 E4.5 ;…"
    assert fit_line("G1 X15.00 Y-15.00 E4.5 ; perimeter", 22) == "G1 X15.00 Y-15.00 E4.5"
    assert fit_line("G1 X15.00 Y-15.00 E4.56789", 10) == "G1 X15.00…"
    assert fit_line("; generated for the cup", 10) == "; generat…"
