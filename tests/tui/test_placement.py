"""Placement in the UI: a file sliced off-centre is refused with the advice, `c` centres
it (as ``--center``), and the print then runs with that placement."""

from __future__ import annotations

import re

from cdprhost.job.state import JobState
from cdprhost.tui.control.live import LiveBackend

from .conftest import make_app, pick_file, shown, wait_for
from .parts import small_part


def _shifted(text: str, by: float) -> str:
    return re.sub(r"([XY])(-?\d+\.\d+)", lambda m: f"{m[1]}{float(m[2]) + by:.2f}", text)


async def test_center_places_an_off_centre_file_and_the_print_uses_it(tmp_path):
    path = tmp_path / "bed200.gcode"  # sliced for a 200 mm bed: the part sits at (100, 100)
    path.write_text(_shifted(small_part(layers=2), 100.0), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=25.0,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    app = make_app(backend)
    async with app.run_test(size=(120, 36)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await pick_file(pilot, path)
        state = await wait_for(pilot, lambda s: s.file.preflight is not None, timeout=30)
        refused = state.file.preflight
        assert not refused.ok and refused.placement == "fits with --offset -100,-100"
        assert "fits with --offset -100,-100: c Center part" in await shown(pilot)
        await pilot.press("c")
        state = await wait_for(
            pilot, lambda s: s.file.preflight is not None and s.file.preflight.ok, timeout=30
        )
        assert state.file.preflight.placement == "shifted by X -100.00, Y -100.00 mm"
        assert "shifted by X -100.00" in await shown(pilot)
        await pilot.press("s", "y")
        state = await wait_for(pilot, lambda s: s.job.state.finished, timeout=120)
        assert state.job.state is JobState.DONE, state.job.reason
