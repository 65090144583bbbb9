"""The real sliced fixture printed end to end on the embedded simulated device."""

from __future__ import annotations

import numpy as np

from tests.e2e.conftest import PrintRun


def test_fixture_print_completes_and_matches_its_estimate(fixture_print: PrintRun):
    r = fixture_print.result
    assert r.status == "completed", r.reason
    assert r.segments == len(fixture_print.record) == len(fixture_print.steps_abs)
    assert abs(r.print_time_s - r.estimated_time_s) <= 0.05 * r.print_time_s


def test_device_executed_exactly_the_planned_steps(fixture_print: PrintRun):
    executed = np.array([rec["steps"] for rec in fixture_print.record])
    np.testing.assert_array_equal(executed, fixture_print.steps_abs)


def test_final_steps_equal_ik_of_the_last_gcode_position(fixture_print: PrintRun):
    """The last executed segment ends exactly on IK(last G-code move end); the file then
    homes (G28), so the device ends at the endstop positions."""
    run = fixture_print
    last_line = max(run.moves_end)
    target = run.moves_end[last_line]
    expected = run.model.steps(run.model.ik(target[None, :]))[0]
    np.testing.assert_array_equal(run.record[-1]["steps"][:3], expected)
    assert run.record[-1]["steps"][3] == round(run.e_final * run.profile.extruder.steps_per_mm)
    home = run.model.steps(np.asarray(run.profile.drive.home_mm, float)[None, :])[0]
    np.testing.assert_array_equal(run.result.final_steps[:3], home)
    assert run.result.final_steps[3] == run.record[-1]["steps"][3]


def test_extruded_length_equals_the_gcode(fixture_print: PrintRun):
    run = fixture_print
    extruded_mm = run.record[-1]["steps"][3] / run.profile.extruder.steps_per_mm
    assert abs(extruded_mm - run.e_final) <= 0.5 / run.profile.extruder.steps_per_mm


def _distance_to_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    denom = np.einsum("ij,ij->i", ab, ab)
    t = np.where(denom > 0, np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0), 0.0)
    closest = a + np.clip(t, 0.0, 1.0)[:, None] * ab
    return np.linalg.norm(p - closest, axis=1)


def test_executed_path_stays_within_0_02_mm_of_the_gcode_path(fixture_print: PrintRun):
    """FK of the executed steps at every segment end and midpoint vs the G-code move it belongs to."""
    run = fixture_print
    steps = np.array([rec["steps"] for rec in run.record], dtype=float)[:, :3]
    prev = np.vstack([steps[:1], steps[:-1]])
    spm = run.model.steps_per_mm
    ends = run.model.fk(steps / spm)
    mids = run.model.fk((steps + prev) / 2 / spm)
    a = np.array([run.moves_start[ln] for ln in run.lines])
    b = np.array([run.moves_end[ln] for ln in run.lines])
    first = np.r_[
        True, run.lines[1:] != run.lines[:-1]
    ]  # a move's first segment starts at the previous move's end
    d_end = _distance_to_segments(ends, a, b)
    d_mid = _distance_to_segments(mids[~first], a[~first], b[~first])
    assert d_end.max() < 0.02, (
        f"worst segment end {d_end.max():.4f} mm at line {run.lines[d_end.argmax()]}"
    )
    assert d_mid.max() < 0.02, f"worst segment midpoint {d_mid.max():.4f} mm"
