"""The slicer's time estimate for a file sliced with the exported profile agrees with ours.

The exported PrusaSlicer printer carries the machine's limits and has the slicer write
retractions as moves (its estimator leaves firmware retraction out), so PrusaSlicer's
own estimate of a part sliced with it lands within 2 % of `check`'s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cdprhost.gcode.slicer_header import read_slicer_figures
from cdprhost.preflight import preflight
from cdprhost.preflight.render import render_text
from cdprhost.profile import load_profile

ROOT = Path(__file__).resolve().parents[2]
SLICED_WITH_EXPORT = [
    ROOT / "examples" / "example.gcode",
    ROOT / "tests" / "profile" / "data" / "boat-exported-prusaslicer.gcode",
]


@pytest.mark.parametrize("path", SLICED_WITH_EXPORT, ids=lambda p: p.stem)
def test_the_slicers_estimate_is_within_two_percent_of_ours(path):
    r = preflight(path, load_profile("paper-prototype"))
    assert r.ok
    assert r.slicer is not None and r.slicer.exported_profile == "paper-prototype"
    assert r.slicer.time_s is not None
    gap = r.estimated_time_s / r.slicer.time_s - 1.0
    assert abs(gap) < 0.02, (
        f"ours {r.estimated_time_s:.0f} s vs the slicer's {r.slicer.time_s:.0f} s"
    )
    text = render_text(r)
    assert "with the limits of the printer exported from profile 'paper-prototype'" in text


def test_a_file_for_another_printer_is_said_to_be_for_its_own_printer():
    path = ROOT / "tests" / "gcode" / "data" / "thirdparty" / "prusaslicer25_mk3s_cube.gcode"
    fig = read_slicer_figures(path)
    assert fig is not None and fig.exported_profile is None and fig.time_s is not None


def test_the_exported_profile_is_read_from_the_config_dump(tmp_path):
    f = tmp_path / "x.gcode"
    f.write_text(
        "G1 X1 E1\n; estimated printing time (normal mode) = 1m 2s\n"
        "; printer_notes = cdprhost profile my machine\n"
    )
    fig = read_slicer_figures(f)
    assert fig is not None and fig.exported_profile == "my machine" and fig.time_s == 62.0
