"""`cdprhost serve` as a client of the printer service (separate processes, as a user runs
them): a server killed mid-print leaves the print running and a new server shows it; the
server's jobs write the CLI's JSON-lines job log; `serve` and `print --attach` watch one
print and see the same state; the web page's device controls are done by the service."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cdprhost.profile import load_profile
from cdprhost.server.service_printer import ServicePrinter
from cdprhost.service import wire
from tests.e2e.processes import PYTHON, SimDeviceProcess, service_pid
from tests.server.conftest import (
    PROFILE,
    ServeProcess,
    multipart,
    printed_to_the_end,
    small_part,
)
from tests.server.test_job_control import _command, _upload
from tests.service.inprocess import serve_in_thread

pytestmark = pytest.mark.timeout(300)


@pytest.fixture
def run_dir(monkeypatch) -> Iterator[Path]:
    """A private run folder for the services these servers start; every service left in it
    is stopped at the end (a service waits for its next front end for a while)."""
    folder = Path(tempfile.mkdtemp(prefix="websvc-", dir="/tmp"))
    monkeypatch.setenv("CDPRHOST_RUN", str(folder))
    yield folder
    for pid_file in folder.glob("*.pid"):
        with contextlib.suppress(ValueError, OSError):
            pid = int(pid_file.read_text())
            if pid != os.getpid():  # (a service in a thread of this test: not a process)
                os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(OSError):
        for path in folder.iterdir():
            path.unlink()
        folder.rmdir()


def _post(server: ServeProcess, path: str, body: Any) -> tuple[int, dict[str, Any]]:
    data = json.dumps(body).encode()
    headers = {"X-Api-Key": server.key, "Content-Type": "application/json"}
    req = urllib.request.Request(server.url + path, data, headers)
    try:
        with urllib.request.urlopen(req, timeout=180) as resp:
            return resp.status, json.loads(resp.read() or b"{}")
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


def _upload_and_print(server: ServeProcess, name: str, text: str) -> None:
    body, ctype = multipart([("print", "true")], (name, text.encode()))
    headers = {"X-Api-Key": server.key, "Content-Type": ctype}
    req = urllib.request.Request(server.url + "/api/files/local", body, headers)
    with urllib.request.urlopen(req, timeout=120) as resp:
        assert resp.status == 201


def _control(server: ServeProcess, action: str, **delta: float) -> tuple[int, str]:
    status, reply = _post(server, "/api/web/control", {"action": action, **delta})
    return status, str(reply.get("done") or reply.get("error"))


def _records(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def test_a_killed_server_leaves_the_print_running_and_a_new_one_shows_it(tmp_path, run_dir):
    folder = tmp_path / "srv"  # the same state (so the same service) for both servers
    first = ServeProcess(folder, "--speedup", "20")
    try:
        _upload_and_print(first, "long.gcode", small_part(12))
        first.wait_job(lambda j: j["state"] == "Printing")
    finally:
        first.proc.kill()  # SIGKILL: nothing of the server runs on
        first.proc.wait(30)
    second = ServeProcess(folder, "--speedup", "20")
    try:
        assert "the printer service is printing long.gcode" in second.banner
        now = second.job()
        assert now["state"] in ("Printing", "Operational"), now
        assert now["job"]["file"]["name"] == "long.gcode"
        assert now["job"]["user"]  # who started it, as the first server was told
        done = second.wait_job(printed_to_the_end, timeout=240)
        assert done["job"]["file"]["name"] == "long.gcode"
    finally:
        code, rest = second.stop()
    assert code == 0, rest
    # the server's job wrote the CLI's JSON-lines log (and its .log beside it)
    logs = sorted((folder / "state").rglob("long-*.jsonl"))
    assert len(logs) == 1, logs
    records = _records(logs[0])
    states = [r["state"] for r in records if r.get("event") == "StateChanged"]
    assert states[0] == "preflight" and states[-1] == "done", states
    assert any(r.get("event") == "Progress" for r in records)
    assert logs[0].with_suffix(".log").is_file()


def test_the_page_controls_are_done_by_the_service_on_its_device(tmp_path, run_dir):
    folder = tmp_path / "srv"
    server = ServeProcess(folder, "--speedup", "50")
    try:
        status, text = _control(server, "jog", dx=5.0)
        assert status == 409 and "home first" in text, text
        assert _control(server, "home") == (200, "homed")
        assert _control(server, "heaters_off") == (200, "heaters off")
        req = urllib.request.Request(server.url + "/api/printer", headers={"X-Api-Key": server.key})
        with urllib.request.urlopen(req, timeout=60) as resp:  # idle: read by the service
            heaters = json.loads(resp.read())["temperature"]
        assert heaters["tool0"]["target"] == 0 and heaters["tool0"]["actual"] > 0, heaters
    finally:
        server.proc.kill()
        server.proc.wait(30)
    # the machine stays homed in the service, whichever server asks: a new one jogs at once
    again = ServeProcess(folder, "--speedup", "50")
    try:
        assert _control(again, "jog", dx=5.0, dz=-2.0) == (200, "jogged")
        status, text = _control(again, "jog", dx=10.0, dy=10.0, dz=-10.0)
        assert status in (200, 409), text  # inside or outside the workspace: said either way
        assert _control(again, "estop") == (200, "emergency stop (motors kept)")
        status, text = _control(again, "home")  # the device is stopped by the e-stop: refused
        assert status == 409 and "stop" in text.lower(), text
        body, ctype = multipart([("print", "true")], ("after.gcode", small_part(2).encode()))
        headers = {"X-Api-Key": again.key, "Content-Type": ctype}
        req = urllib.request.Request(again.url + "/api/files/local", body, headers)
        with pytest.raises(urllib.error.HTTPError) as refused:  # nobody checked the machine
            urllib.request.urlopen(req, timeout=120)
        assert refused.value.code == 409
        text = json.loads(refused.value.read())["error"]
        assert "fault" in text and "--clear-fault" in text and "nothing started" in text
    finally:
        code, rest = again.stop()
    assert code == 0, rest


def test_the_page_e_stop_during_a_print_is_the_jobs(tmp_path, run_dir):
    server = ServeProcess(tmp_path / "srv", "--speedup", "10")
    try:
        _upload_and_print(server, "part.gcode", small_part(30))
        server.wait_job(lambda j: j["state"] == "Printing")
        status, text = _control(server, "home")
        assert status == 409 and "a print is running" in text, text
        assert _control(server, "estop") == (200, "emergency stop (motors kept)")
        ended = server.wait_job(lambda j: "error" in j or j["state"] != "Printing")
        assert "emergency stop" in json.dumps(ended).lower(), ended
    finally:
        code, rest = server.stop()
    assert code == 0, rest


@pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")
def test_serve_and_print_attach_watch_one_print_and_see_the_same_state(tmp_path, run_dir):
    state = tmp_path / "srv" / "state"
    with SimDeviceProcess(tmp_path, "--speedup", "20") as dev:
        server = ServeProcess(tmp_path / "srv", "--port", dev.path)
        watcher = None
        try:
            _upload_and_print(server, "part.gcode", small_part(10))
            server.wait_job(lambda j: j["state"] == "Printing")
            report = tmp_path / "watched.json"
            watcher = subprocess.Popen(
                [*PYTHON, "print", "--attach", "--port", dev.path, "--json", str(report)],
                env={**os.environ, "CDPRHOST_STATE": str(state)},
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            assert _post(server, "/api/job", {"command": "pause", "action": "pause"})[0] == 204
            server.wait_job(lambda j: j["state"] == "Paused")
            assert _post(server, "/api/job", {"command": "pause", "action": "resume"})[0] == 204
            final = server.wait_job(printed_to_the_end, timeout=240)
            out, err = watcher.communicate(timeout=120)
        finally:
            if watcher is not None and watcher.poll() is None:
                watcher.kill()
            code, rest = server.stop()
        assert code == 0, rest
        assert watcher.returncode == 0, out + err
        result = json.loads(report.read_text())
        # one print, one service, one state: completed to the same layer the server shows
        assert result["status"] == "completed" and result["last_layer"] == 10
        assert final["job"]["file"]["name"] == "part.gcode"
        assert "pause" in (out + err).lower()  # the watcher saw the pause the server asked
        assert service_pid(dev.path, state)  # the service outlives both front ends


def test_over_the_service_a_busy_printer_refuses_and_pause_resume_cancel_work(
    make_server, run_dir, monkeypatch
):
    """The OctoPrint job routes on a server whose printer is a client of the service."""
    services = serve_in_thread(monkeypatch, idle_s=30.0)
    printer = ServicePrinter(load_profile(PROFILE), speedup=10.0)
    printer.connect()
    server = make_server(printer=printer)
    try:
        assert _upload(server, "first.gcode", layers=40).status == 201
        server.wait_job(lambda j: j["state"] == "Printing")
        assert services[0].job_running  # the print runs in the service
        second = _upload(server, "second.gcode")
        assert second.status == 409 and "first.gcode" in second.json()["error"]
        assert _command(server, command="pause", action="pause").status == 204
        server.wait_job(lambda j: j["state"] == "Paused")
        assert _command(server, command="start").status == 409  # a paused job is still a job
        assert _command(server, command="pause", action="resume").status == 204
        job = server.wait_job(lambda j: j["state"] == "Printing" and j["progress"]["filepos"])
        text, pos = small_part(layers=40).encode(), job["progress"]["filepos"]
        assert 0 < pos < len(text) and text[pos - 1 : pos] == b"\n"
        assert _command(server, command="cancel").status == 204
        job = server.wait_job(lambda j: j["state"] == "Operational")
        assert job["progress"]["completion"] < 100
        assert printer.status().job.state.value == "cancelled"
        assert _command(server, command="cancel").status == 409  # nothing left to cancel
    finally:
        for service in services:
            service.shutdown_job("test over")


def test_one_wire_vocabulary_for_the_device_and_one_job_message():
    # the page's device commands are the device session's operations: no second way to home
    with pytest.raises(wire.WireError, match="op"):
        wire.decode_request(b'{"op": "device", "action": "home", "device": {"profile": {}}}')
    assert isinstance(wire.decode_request(b'{"op": "home", "id": 3}'), wire.Home)
    assert isinstance(wire.decode_request(b'{"op": "pause", "id": 3}'), wire.Pause)
    info = wire.decode_reply(
        b'{"msg": "job", "gcode": "/x.gcode", "state": "printing", "started_by": "PrusaSlicer",'
        b' "started_at": 1.5}'
    )
    assert isinstance(info, wire.JobInfo) and info.started_by == "PrusaSlicer"
    assert wire.decode_reply(b'{"msg": "job", "gcode": "/x.gcode"}').state == "idle"
    with pytest.raises(wire.UnknownMessage):  # a newer service's message: a client skips it
        wire.decode_reply(b'{"msg": "speed", "percent": 120}')
    later = wire.decode_reply(b'{"msg": "note", "text": "hi", "added_later": 1}')
    assert isinstance(later, wire.Note) and later.text == "hi"  # a newer field: ignored


def test_a_service_that_dies_mid_print_is_said_and_the_server_prints_again(tmp_path, run_dir):
    from cdprhost.service.client import embedded_files

    server = ServeProcess(tmp_path / "srv", "--speedup", "10")
    try:
        _upload_and_print(server, "doomed.gcode", small_part(30))
        server.wait_job(lambda j: j["state"] == "Printing")
        saved = os.environ.get("CDPRHOST_STATE")
        os.environ["CDPRHOST_STATE"] = str(tmp_path / "srv" / "state")
        try:
            pid = embedded_files().read_pid()
        finally:
            if saved is not None:
                os.environ["CDPRHOST_STATE"] = saved
        assert pid is not None
        os.kill(pid, signal.SIGKILL)  # the service, not the server
        failed = server.wait_job(lambda j: "went away" in j.get("error", ""), timeout=60)
        assert failed["job"]["file"]["name"] == "doomed.gcode"
        # a new service prints it (without the M109 wait: heating is not what it proves)
        _upload_and_print(server, "next.gcode", small_part(2, heat_wait=False))
        done = server.wait_job(printed_to_the_end)
        assert done["job"]["file"]["name"] == "next.gcode"
    finally:
        code, rest = server.stop()
    assert code == 0, rest


def test_a_stopped_server_never_holds_the_print_and_shows_its_end_once_continued(tmp_path, run_dir):
    server = ServeProcess(tmp_path / "srv", "--speedup", "20")
    try:
        _upload_and_print(server, "held.gcode", small_part(12))
        server.wait_job(lambda j: j["state"] == "Printing")
        from cdprhost.service.client import embedded_files

        saved = os.environ.get("CDPRHOST_STATE")
        os.environ["CDPRHOST_STATE"] = str(tmp_path / "srv" / "state")
        try:
            files = embedded_files()
        finally:
            if saved is not None:
                os.environ["CDPRHOST_STATE"] = saved
        server.proc.send_signal(signal.SIGSTOP)  # a hung front end: reads nothing
        try:
            logs = tmp_path / "srv" / "state"
            ended = wait_for_log_end(logs, "held-*.jsonl", timeout=240)
        finally:
            server.proc.send_signal(signal.SIGCONT)
        assert ended == "done"  # the service printed to the end meanwhile
        done = server.wait_job(printed_to_the_end, timeout=60)
        assert done["job"]["file"]["name"] == "held.gcode"
        assert files.read_pid() is not None
    finally:
        code, rest = server.stop()
    assert code == 0, rest


def wait_for_log_end(folder: Path, pattern: str, timeout: float) -> str:
    """The last state the job's JSON-lines log records once the job has ended (bounded)."""
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for path in folder.rglob(pattern):
            try:
                records = _records(path)
            except json.JSONDecodeError:  # a line being written: read again
                continue
            states = [
                r["state"]
                for r in records
                if r.get("event") == "StateChanged"
                and r.get("state") in ("done", "failed", "cancelled")
            ]
            if states:
                return str(states[-1])
        time.sleep(0.2)
    raise AssertionError(f"no job ended in {folder} within {timeout:g} s")
