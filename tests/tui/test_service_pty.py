"""A TUI's print lives in the printer service: a headless TUI in its own process prints on a
pty sim-device and is killed or stopped (SIGSTOP) mid-print; the print goes on to the end
(the service's JSON-lines log says so), and a new TUI attaches and shows it. (Accelerated
device, a small part: the 1x runs under load are measured by hand.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cdprhost.job.state import JobState
from cdprhost.tui.control.service_backend import ServiceBackend
from tests.e2e.processes import (
    SimDeviceProcess,
    kill_and_wait,
    printing_point,
    service_pid,
    square_part,
    start_print,
)

from .conftest import make_app, wait_for
from .pty_terminal import PtyTerminal, tui_argv

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(300),
]
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def state(monkeypatch, tmp_path):
    folder = tmp_path / "state"
    monkeypatch.setenv("CDPRHOST_STATE", str(folder))
    return folder


def _front(port: str, gcode: Path) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.tui.service_front", port, str(gcode)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ),
    )
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    if line != "printing":
        proc.kill()
        raise AssertionError(f"the TUI did not start printing: {line!r} {proc.stderr.read()}")
    return proc


def _job_log(state: Path) -> list[dict]:
    logs = sorted((state / "jobs").glob("part-*.jsonl"))
    assert len(logs) == 1, logs
    return [json.loads(line) for line in logs[0].read_text().splitlines() if line.strip()]


def _completed(state: Path) -> bool:
    return any("completed" in json.dumps(r) for r in _job_log(state)[-5:])


async def test_a_killed_tui_leaves_the_print_running_and_a_new_tui_shows_it(state, tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=8)
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        front = _front(dev.path, gcode)
        service = service_pid(dev.path, state)
        front.kill()  # SIGKILL: no goodbye, no cancel
        front.wait(20)
        backend = ServiceBackend("paper-prototype")
        app = make_app(backend, port=dev.path)
        try:
            async with app.run_test(size=(100, 32)) as pilot:
                now = await wait_for(
                    pilot, lambda s: s.job_path == str(gcode), timeout=60, what="the print"
                )
                assert now.job.state is not JobState.IDLE or now.job_id
                end = await wait_for(
                    pilot, lambda s: s.job.state.finished, timeout=240, what="its end"
                )
                assert end.job.state is JobState.DONE, end.job.reason
                assert end.job.layer + 1 == 8
        finally:
            backend.close()
        assert _completed(state)  # the job's JSON-lines log, written by the service
        assert service_pid(dev.path, state) == service  # one service ran it all
        assert not dev.stderr_has("host watchdog")
        kill_and_wait(service)


def test_a_stopped_tui_does_not_stop_the_print(state, tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=8)
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        front = _front(dev.path, gcode)
        service = service_pid(dev.path, state)
        try:
            front.send_signal(signal.SIGSTOP)
            before = len(dev.records())
            time.sleep(8.0)  # the service keeps streaming meanwhile
            during = len(dev.records()) - before
            front.send_signal(signal.SIGCONT)
            out, err = front.communicate(timeout=240)
        finally:
            if front.poll() is None:
                front.kill()
        assert "end done" in out, out + err
        assert during > 0  # the device moved while the UI was stopped
        assert _completed(state)
        assert not dev.stderr_has("host watchdog")
        kill_and_wait(service)


async def test_a_tui_and_print_attach_see_the_same_print(state, tmp_path):
    """``cdprhost print`` started it (the service's link, no device session); a TUI joins
    (sharing that link) and both see the same end."""
    gcode = square_part(tmp_path / "part.gcode", layers=6)
    report = tmp_path / "report.json"
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        cli = start_print(gcode, dev.path, state, "--json", str(report))
        try:
            printing_point(gcode, state)
            service = service_pid(dev.path, state)
            backend = ServiceBackend("paper-prototype")
            app = make_app(backend, port=dev.path)
            try:
                async with app.run_test(size=(100, 32)) as pilot:
                    await wait_for(
                        pilot, lambda s: s.job_path == str(gcode), timeout=60, what="the print"
                    )
                    end = await wait_for(
                        pilot, lambda s: s.job.state.finished, timeout=240, what="its end"
                    )
                    # after the print the UI holds the device: it answers
                    await wait_for(
                        pilot, lambda s: s.device is not None, timeout=30, what="the device"
                    )
            finally:
                backend.close()
            out, err = cli.communicate(timeout=120)
        finally:
            if cli.poll() is None:
                cli.kill()
        assert cli.returncode == 0, out + err
        result = json.loads(report.read_text())
        assert result["status"] == "completed" and end.job.state is JobState.DONE
        assert end.job.layer + 1 == result["last_layer"] == 6
        kill_and_wait(service)


async def test_a_killed_tui_on_the_embedded_device_leaves_its_print_to_a_new_tui(state, tmp_path):
    """No port: the embedded simulated device's service is one per state folder, found by
    a new TUI as a port's is (the rule `print`, `tui` and `serve` share)."""
    from cdprhost.tui.control.backend import EMBEDDED

    gcode = square_part(tmp_path / "part.gcode", layers=8)
    front = _front(EMBEDDED, gcode)
    service = service_pid(None, state)
    try:
        front.kill()  # SIGKILL: no goodbye, no cancel
        front.wait(20)
        backend = ServiceBackend("paper-prototype")
        app = make_app(backend, port=EMBEDDED)
        try:
            async with app.run_test(size=(100, 32)) as pilot:
                await wait_for(
                    pilot, lambda s: s.job_path == str(gcode), timeout=60, what="the print"
                )
                end = await wait_for(
                    pilot, lambda s: s.job.state.finished, timeout=240, what="its end"
                )
                assert end.job.state is JobState.DONE, end.job.reason
                assert end.job.layer + 1 == 8
        finally:
            backend.close()
        assert _completed(state)
        assert service_pid(None, state) == service
    finally:
        kill_and_wait(service)


def test_sighup_to_a_tui_on_a_pty_leaves_its_print_running_to_the_end(state, tmp_path):
    """The terminal closes mid-print (SIGHUP): the TUI quits, says in its log that the print
    goes on in the service, and the print completes (before: stopped like a cancel)."""
    from cdprhost.job.resume import resume_path_for

    gcode = square_part(tmp_path / "part.gcode", layers=10)
    with SimDeviceProcess(tmp_path, "--speedup", "10") as dev:
        env = {**os.environ, "CDPRHOST_STATE": str(state)}
        env.pop("TEXTUAL", None)
        argv = tui_argv("--port", dev.path, str(gcode), "--profile", "paper-prototype")
        tui = PtyTerminal(argv, size=(120, 40), env=env)
        service = None
        try:
            point = resume_path_for(gcode, state / "jobs")
            deadline = time.monotonic() + 120
            while not point.exists():  # s, then y to the question, once the file is checked
                assert time.monotonic() < deadline, "the TUI did not start the print"
                assert tui.proc.poll() is None, tui.screen()[-500:]
                tui.type("s")
                time.sleep(1.0)
                tui.type("y")
                time.sleep(2.0)
            printing_point(gcode, state)
            service = service_pid(dev.path, state)
            tui.proc.send_signal(signal.SIGHUP)
            assert tui.proc.wait(30) == 0
            deadline = time.monotonic() + 240
            while not _completed(state):
                assert time.monotonic() < deadline, _job_log(state)[-3:]
                time.sleep(0.5)
        finally:
            tui.stop()
            if service is not None:
                kill_and_wait(service)
        log = (state / "tui" / "tui.log").read_text()
        assert "SIGHUP: the terminal UI quits" in log and "goes on in the printer service" in log
        assert not any("cancel" in json.dumps(r) for r in _job_log(state))
        assert not dev.stderr_has("host watchdog")


async def test_start_pressed_twice_before_the_print_shows_starts_one_print(state, tmp_path):
    """s, y, s, y in quick succession: the second start comes before the service's first
    event reaches the screen (the job still reads idle); it starts nothing, and the one print
    is followed to its end (before: a second job took the first one's events and the first
    waited forever)."""
    gcode = square_part(tmp_path / "part.gcode", layers=4)
    with SimDeviceProcess(tmp_path, "--speedup", "20") as dev:
        backend = ServiceBackend("paper-prototype")
        app = make_app(backend, port=dev.path, open_file=str(gcode))
        try:
            async with app.run_test(size=(100, 32)) as pilot:
                await wait_for(
                    pilot,
                    lambda s: s.connected and s.file.preflight is not None,
                    timeout=120,
                    what="connected, the file checked",
                )
                for key in "sysy":
                    await pilot.press(key)
                first = app.state.job_id
                end = await wait_for(
                    pilot, lambda s: s.job.state.finished, timeout=240, what="its end"
                )
                assert end.job.state is JobState.DONE, end.job.reason
                assert end.job_id == first == 1
                assert end.job.layer + 1 == 4
        finally:
            backend.close()
        kill_and_wait(service_pid(dev.path, state))
