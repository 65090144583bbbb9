"""Fail-safe behaviour with `cdprhost print` and `cdprhost sim-device` as separate processes
on a real pty: a killed host, a stopped host, a failed connect, an unwritable log.

The host is the printer service `cdprhost print` starts (the job and the link live there;
the print command is only its front end): it is killed or stopped once its resume point
shows motion executed (the point is written while printing). Waits poll conditions with
generous deadlines.
"""

from __future__ import annotations

import json
import signal
import sys

import pytest
import serial

from cdprhost.job.resume import ResumePoint, resume_path_for
from cdprhost.link import open_link
from cdprhost.link.errors import PortBusy
from firmware_protocol.messages import ErrorCode, Flag
from tests.e2e.processes import (
    SimDeviceProcess,
    kill_and_wait,
    printing_point,
    signal_service,
    square_part,
    start_print,
    wait_until,
)

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(240),
]

SPEEDUP = "20"


def _printing_point(gcode, state) -> ResumePoint:
    """Wait until the job's resume point names an executed segment."""
    return printing_point(gcode, state)  # type: ignore[return-value]


def _kill_mid_print(tmp_path, dev, gcode, state, *extra):
    """Kill the host (the printer service) once it is printing; the resume point it left
    (read after the kill: the host may have saved a newer one between the poll and the
    kill). Its front end then says the service went away."""
    host = start_print(gcode, dev.path, state, *extra)
    _printing_point(gcode, state)
    signal_service(dev.path, state, signal.SIGKILL)
    out, err = host.communicate(timeout=60)
    assert host.returncode == 1 and "printer service went away" in err, out + err
    return ResumePoint.load(resume_path_for(gcode, state / "jobs"))


def _status_after_watchdog(dev):
    """The device's state once its watchdog has noticed the host is gone."""
    wait_until(lambda: dev.stderr_has("host watchdog"), 60, "the device's watchdog")
    link = open_link(dev.path)
    try:
        return link.identity, link.request_status()
    finally:
        link.close()


def test_killed_host_trips_the_watchdog_then_a_new_print_completes(tmp_path):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode")
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        _kill_mid_print(tmp_path, dev, gcode, state)
        _, st = _status_after_watchdog(dev)
        assert st.faulted and st.last_error == ErrorCode.WATCHDOG
        assert st.hotend_target_c == 0 and st.bed_target_c == 0  # heaters off
        assert st.enabled_mask  # motors held: a cable robot must not drop its effector
        host = start_print(gcode, dev.path, state, "--json", str(tmp_path / "again.json"))
        out, err = host.communicate(timeout=200)
        assert host.returncode == 0, out + err
        result = json.loads((tmp_path / "again.json").read_text())
        assert result["status"] == "completed"
        assert any("watchdog" in n and "cleared" in n for n in result["notices"]), result
        assert "has a resume point" in err  # it offered the point, then started over
        assert "Traceback" not in err


@pytest.mark.parametrize("placement", [(), ("--center",)], ids=["as-sliced", "centred"])
def test_killed_host_then_resume_continues_exactly_where_the_device_stopped(tmp_path, placement):
    """The resumed job rebuilds the dead job's program (its placement too: ``--resume``
    alone continues a ``--center`` print at the same physical point)."""
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode")
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        point = _kill_mid_print(tmp_path, dev, gcode, state, *placement)
        assert point.job_setup().center is bool(placement)
        identity, st = _status_after_watchdog(dev)
        stopped_at = st.segments_done  # the device's own last executed segment
        assert stopped_at >= point.device_segment
        first_run = [r for r in dev.records() if "error" not in r]
        last = next(r for r in reversed(first_run) if r["seq"] == stopped_at)
        report = tmp_path / "resume.json"
        host = start_print(gcode, dev.path, state, "--resume", "--yes", "--json", str(report))
        out, err = host.communicate(timeout=200)
        assert host.returncode == 0, out + err
        result = json.loads(report.read_text())
        assert result["status"] == "completed" and result["last_layer"] == 12
        if stopped_at > point.device_segment:  # killed between saves: the device knew better
            assert any("after the resume point was saved" in n for n in result["notices"])
        resumed = [r for r in dev.records() if r["seq"] > stopped_at]
        # the approach lowers the effector exactly onto the end of the device's last segment
        assert any(r["steps"][:3] == last["steps"][:3] for r in resumed)
        assert not resume_path_for(gcode, state / "jobs").exists()  # completed: point removed


def _open_when_free(port: str):
    """A link on ``port``, or None while the killed service's hold on it is still being
    released (seen once in about eight runs, also before the service had a device
    session: the lock outlives the process's exit by a moment; fuser then finds no holder)."""
    try:
        return open_link(port)
    except PortBusy:
        return None


def test_stopped_host_trips_the_device_watchdog(tmp_path):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode")
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        host = start_print(gcode, dev.path, state)
        pid = None
        try:
            _printing_point(gcode, state)
            pid = signal_service(dev.path, state, signal.SIGSTOP)
            wait_until(lambda: dev.stderr_has("host watchdog"), 60, "the device's watchdog")
        finally:
            if pid is not None:
                kill_and_wait(pid)
            host.kill()
            host.wait(20)
        link = wait_until(lambda: _open_when_free(dev.path), 10, "the port free again")
        st = link.request_status()
        link.close()
        assert st.faulted and st.last_error == ErrorCode.WATCHDOG
        assert st.hotend_target_c == 0 and st.bed_target_c == 0
        assert not st.flags & Flag.MOVING


def test_failed_connects_keep_the_resume_point(tmp_path):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode")
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        _kill_mid_print(tmp_path, dev, gcode, state)
        path = resume_path_for(gcode, state / "jobs")
        saved = path.read_bytes()
        with serial.Serial(dev.path, 250000, exclusive=True):  # someone else holds the port
            host = start_print(gcode, dev.path, state, "--resume", "--yes")
            out, err = host.communicate(timeout=60)
        assert host.returncode == 1 and "in use" in err and "Traceback" not in err
        assert path.read_bytes() == saved
        host = start_print(gcode, str(tmp_path / "no-such-port"), state, "--resume", "--yes")
        out, err = host.communicate(timeout=60)
        assert host.returncode == 2 and "no such port" in err and "Traceback" not in err
        assert path.read_bytes() == saved


def test_a_log_on_dev_full_stops_before_anything_moves(tmp_path):
    state = tmp_path / "state"
    gcode = square_part(tmp_path / "part.gcode")
    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        host = start_print(gcode, dev.path, state, "--log", "/dev/full")
        out, err = host.communicate(timeout=60)
        assert host.returncode == 1, out + err
        assert "Traceback" not in err and "Traceback" not in out
        assert "job log /dev/full: No space left on device; nothing moved" in out + err
        link = open_link(dev.path)
        st = link.request_status()
        link.close()
        assert st.hotend_target_c == 0 and st.segments_done == 0


def test_fuzzed_frames_over_the_pty_then_a_clean_handshake(tmp_path):
    from firmware_protocol.framing import Kind, encode_frame
    from tests.protocol.test_proto_fuzz import fuzz_frames

    with SimDeviceProcess(tmp_path, "--speedup", SPEEDUP) as dev:
        with serial.Serial(dev.path, 250000, timeout=0, exclusive=True) as port:
            seq = 0
            chunk = bytearray()
            for frame in fuzz_frames(20_000, seed=31):
                if isinstance(frame, tuple):
                    what, payload = frame
                    if what == "data":
                        frame = encode_frame(Kind.DATA, seq, 0, payload)
                        seq = (seq + 1) % 256
                    else:
                        frame = encode_frame(Kind.URGENT, 0, 0, payload)
                chunk += frame
                if len(chunk) > 2048:
                    port.write(chunk)
                    port.reset_input_buffer()  # nobody reads the answers
                    chunk.clear()
            port.write(chunk)
        assert dev.proc.poll() is None  # still running
        link = open_link(dev.path)
        if link.request_status().faulted:  # the fuzz left a fault (a BAD_COMMAND, an e-stop)
            link.clear_fault()
        st = link.request_status()
        link.close()
        assert st.flags & Flag.SYNCED and not st.faulted
