"""`cdprhost print` on a pty sim-device at 1x, sent SIGINT, SIGHUP or SIGTERM mid-print:
it cancels like an operator (stop within the motion sent, park, heaters off), records
the job and its resume point, and leaves the device at rest with no watchdog fault.
(Exit times are figures of ``python bench/stop.py --signals``, never asserted here.)"""

from __future__ import annotations

import json
import signal
import sys

import pytest

from cdprhost.job.resume import ResumePoint
from cdprhost.link import open_link
from cdprhost.profile import load_profile
from tests.e2e.processes import SimDeviceProcess, printing_point, square_part, start_print

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(240),
]


@pytest.mark.parametrize(
    "sig", [signal.SIGINT, signal.SIGHUP, signal.SIGTERM], ids=lambda s: s.name
)
def test_a_signal_mid_print_cancels_and_leaves_the_device_safe(tmp_path, sig):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode", layers=30)
    report = tmp_path / "result.json"
    with SimDeviceProcess(tmp_path, "--speedup", "1") as dev:
        host = start_print(gcode, dev.path, state, "--json", str(report))
        printing_point(gcode, state)
        host.send_signal(sig)
        out, err = host.communicate(timeout=120)
        assert host.returncode == 1, out + err  # cancelled, not completed
        assert "Traceback" not in err
        result = json.loads(report.read_text())
        assert result["status"] == "cancelled" and result["reason"] == sig.name, result
        link = open_link(dev.path)
        try:
            st = link.request_status()
        finally:
            link.close()
        assert not st.faulted and not st.busy  # at rest, stopped by the host, not its watchdog
        assert st.hotend_target_c == 0 and st.bed_target_c == 0
        assert st.enabled_mask  # motors held
        assert not dev.stderr_has("host watchdog")
        point = ResumePoint.load(result["resume_file"])
        assert point.reason == "cancelled"
        # the resume point names a segment the device executed, before the host's stop moves
        assert 0 < point.device_segment < st.segments_done
        records = [r for r in dev.records() if "error" not in r]
        assert point.device_segment in {r["seq"] for r in records}
        # after the last program segment: no extrusion, only the retract (then the lift)
        after = [r["steps"][3] for r in records if r["seq"] >= point.device_segment]
        assert all(b <= a for a, b in zip(after, after[1:]))
        ext = load_profile("paper-prototype").extruder
        assert after[0] - after[-1] == round(ext.retract_mm * ext.steps_per_mm)
