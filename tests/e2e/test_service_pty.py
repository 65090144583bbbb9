"""The print lives in the printer service, not in its front end: `cdprhost print` on a pty
sim-device, its process stopped (SIGSTOP) or killed mid-print; the print goes on to the end
and `cdprhost print --attach` shows it. (The full runs at 1x under load are measured by
hand; these are shortened: an accelerated device, a small part.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from cdprhost.link import open_link
from tests.e2e.processes import (
    PYTHON,
    SimDeviceProcess,
    printing_point,
    service_pid,
    signal_service,
    square_part,
    start_print,
)

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(300),
]


def _attach(port: str, state, report) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "CDPRHOST_STATE": str(state)}
    return subprocess.run(
        [*PYTHON, "print", "--attach", "--port", port, "--json", str(report)],
        capture_output=True,
        text=True,
        env=env,
        timeout=240,
    )


def _device_at_rest(port: str) -> None:
    link = open_link(port)
    try:
        st = link.request_status()
    finally:
        link.close()
    assert not st.faulted and not st.busy


@pytest.mark.parametrize("how", ["killed", "stopped"])
def test_the_print_outlives_its_front_end_and_a_new_one_attaches(tmp_path, how):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode", layers=8)
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        front = start_print(gcode, dev.path, state)
        try:
            printing_point(gcode, state)
            service = service_pid(dev.path, state)
            front.send_signal(signal.SIGKILL if how == "killed" else signal.SIGSTOP)
            report = tmp_path / "watched.json"
            watched = _attach(dev.path, state, report)
        finally:
            front.kill()
            front.wait(20)
        assert watched.returncode == 0, watched.stdout + watched.stderr
        assert "status: completed" in watched.stdout and "Traceback" not in watched.stderr
        result = json.loads(report.read_text())
        assert result["status"] == "completed" and result["last_layer"] == 8
        assert service_pid(dev.path, state) == service  # the one service ran it all
        _device_at_rest(dev.path)
        assert not dev.stderr_has("host watchdog")


def test_attach_without_a_print_says_so(tmp_path):
    state = tmp_path / "state"
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        watched = _attach(dev.path, state, tmp_path / "r.json")
    assert watched.returncode == 1 and "no printer service runs" in watched.stderr
    assert "Traceback" not in watched.stderr


def test_a_signal_to_the_service_cancels_like_the_operator(tmp_path):
    """SIGTERM to the service (a shutdown of the print PC): stop, park, heaters off; its
    front end reports the cancel."""
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode", layers=30)
    report = tmp_path / "result.json"
    with SimDeviceProcess(tmp_path, "--speedup", "1") as dev:
        front = start_print(gcode, dev.path, state, "--json", str(report))
        printing_point(gcode, state)
        signal_service(dev.path, state, signal.SIGTERM)
        out, err = front.communicate(timeout=120)
        assert front.returncode == 1, out + err
        result = json.loads(report.read_text())
        assert result["status"] == "cancelled" and result["reason"] == "SIGTERM", result
        link = open_link(dev.path)
        try:
            st = link.request_status()
        finally:
            link.close()
        assert not st.faulted and not st.busy and st.hotend_target_c == 0
        assert not dev.stderr_has("host watchdog")
