"""The printer service with its front ends, in one test process (the service in a thread,
the embedded device): the key, two front ends seeing one print, front ends that leave or
stop reading and never stop it, one print at a time."""

from __future__ import annotations

import os
import queue
import shutil
import socket
import stat
import tempfile
import time

import pytest

from cdprhost.cli.main import main
from cdprhost.job.state import JobSnapshot, JobState, reduce
from cdprhost.profile import load_profile
from cdprhost.service import clients, wire
from cdprhost.service.client import ServiceClient, attach, connect
from tests.e2e.processes import square_part, wait_until
from tests.service.inprocess import serve_in_thread


@pytest.fixture
def run_dir(monkeypatch, tmp_path):
    """A short private run folder (a socket's path is at most 107 bytes) and state."""
    folder = tempfile.mkdtemp(prefix="svc-", dir="/tmp")
    monkeypatch.setenv("CDPRHOST_RUN", folder)
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def _start(tmp_path, layers=6, speedup=30.0) -> wire.Start:
    gcode = square_part(tmp_path / "part.gcode", layers=layers)
    return wire.Start(
        job=wire.StartJob(
            gcode=str(gcode),
            profile=load_profile("paper-prototype").model_dump(mode="json"),
            speedup=speedup,
            log_path=str(tmp_path / "job.jsonl"),
        )
    )


def _follow(client: ServiceClient, until=None, snap=None, timeout=120.0):
    """Fold a client's events (on ``snap``) until its result (or ``until(snapshot)``):
    (snapshot, result)."""
    snap, end = snap or JobSnapshot(), time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            message = client.inbox.get(timeout=0.5)
        except queue.Empty:
            continue
        assert message is not None, client.gone
        if isinstance(message, wire.EventMsg):
            snap = reduce(snap, wire.event_from_json(message.event))
            if until is not None and until(snap):
                return snap, None
        elif isinstance(message, wire.ResultMsg):
            return snap, message
    raise AssertionError("no result in time")


def _reply(client: ServiceClient) -> wire.Reply | None:
    """The next reply among the events a client receives (None: none yet)."""
    try:
        message = client.inbox.get(timeout=1)
    except queue.Empty:
        return None
    return message if isinstance(message, wire.Reply) else None


def _without_history(snap: JobSnapshot) -> JobSnapshot:
    return JobSnapshot(**{**snap.__dict__, "temperature_history": ()})


def test_the_service_refuses_a_client_without_its_key(run_dir, monkeypatch, tmp_path):
    serve_in_thread(monkeypatch)
    first = attach(None, "test", replay=False)
    try:
        files = first.files
        assert stat.S_IMODE(os.stat(run_dir).st_mode) == 0o700
        assert stat.S_IMODE(files.socket.stat().st_mode) == 0o600
        assert stat.S_IMODE(files.key.stat().st_mode) == 0o600
        for key in ("", "0" * 32):
            with socket.socket(socket.AF_UNIX) as raw:
                raw.connect(str(files.socket))
                raw.sendall(wire.encode(wire.Hello(v=wire.VERSION, key=key)))
                answer = wire.decode_reply(raw.makefile("rb").readline())
                assert not answer.ok and "key" in answer.error
                assert raw.recv(100) == b""  # and hung up
        with socket.socket(socket.AF_UNIX) as raw:  # no hello: nothing is obeyed
            raw.connect(str(files.socket))
            raw.sendall(wire.encode(wire.Estop()))
            assert raw.makefile("rb").readline() == b""
    finally:
        first.close()


def test_two_front_ends_see_the_same_print(run_dir, monkeypatch, tmp_path):
    serve_in_thread(monkeypatch)
    first = attach(None, "first", replay=False)
    first.send(_start(tmp_path))
    so_far, _ = _follow(
        first, until=lambda s: s.state is JobState.PRINTING and s.segments_done > 50
    )
    second = connect(first.files, "second")  # late: the journal brings it up to date
    try:
        a, result_a = _follow(first, snap=so_far)
        b, result_b = _follow(second)
    finally:
        first.close()
        second.close()
    assert result_a == result_b and result_a.result["status"] == "completed"
    assert b.state is JobState.DONE and b.layer == a.layer and b.line == a.line
    assert _without_history(a) == _without_history(b)


def test_a_front_end_that_leaves_never_stops_the_print(run_dir, monkeypatch, tmp_path):
    serve_in_thread(monkeypatch)
    first = attach(None, "first", replay=False)
    first.send(_start(tmp_path))
    _follow(first, until=lambda s: s.state is JobState.PRINTING)
    files = first.files
    first.sock.close()  # gone without a word (a crash)
    time.sleep(1.0)
    again = connect(files, "again")
    try:
        snap, result = _follow(again)
    finally:
        again.close()
    assert result.result["status"] == "completed" and snap.state is JobState.DONE


def test_a_front_end_that_stops_reading_is_dropped_and_the_print_goes_on(
    run_dir, monkeypatch, tmp_path
):
    monkeypatch.setattr(clients, "MAX_BACKLOG", 50)
    serve_in_thread(monkeypatch)
    first = attach(None, "first", replay=False)
    stuck = socket.socket(socket.AF_UNIX)  # says hello, then never reads again
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stuck.connect(str(first.files.socket))
    key = first.files.key.read_text().strip()
    stuck.sendall(wire.encode(wire.Hello(v=wire.VERSION, key=key, client="stuck")))
    first.send(_start(tmp_path, layers=8))
    try:
        snap, result = _follow(first)
        assert result.result["status"] == "completed"
        stuck.settimeout(10)
        received = b""
        while chunk := stuck.recv(65536):  # what it was sent before it was dropped, then EOF
            received += chunk
        assert received.count(b"\n") < snap.segments_done  # it did not get the whole print
    finally:
        stuck.close()
        first.close()


def test_one_print_at_a_time(run_dir, monkeypatch, tmp_path):
    serve_in_thread(monkeypatch)
    first = attach(None, "first", replay=False)
    first.send(_start(tmp_path, speedup=5.0))
    so_far, _ = _follow(first, until=lambda s: s.state is JobState.PRINTING)
    second = connect(first.files, "second", replay=False)
    try:
        # its own file: the part's again in the same place would rewrite the one printing
        (tmp_path / "second").mkdir()
        second.send(_start(tmp_path / "second"))
        reply = wait_until(lambda: _reply(second), 30, "a reply")
        assert not reply.ok and "--attach" in reply.error
        second.send(wire.Cancel(reason="test"))  # any front end may stop it
        snap, result = _follow(first, snap=so_far)
        assert result.result["status"] == "cancelled", result
        assert result.result["reason"] == "test", result
        assert snap.state is JobState.CANCELLED
    finally:
        first.close()
        second.close()


def test_print_says_why_when_a_print_already_runs(run_dir, monkeypatch, tmp_path, capsys):
    from cdprhost.cli.commands import print_cmd

    serve_in_thread(monkeypatch)
    first = attach(None, "first", replay=False)
    first.send(_start(tmp_path, speedup=2.0))
    _follow(first, until=lambda s: s.state is JobState.PRINTING)
    # the next `print` finds this service (as it would a device's) and is refused
    monkeypatch.setattr(
        print_cmd, "attach", lambda *a, **k: connect(first.files, "print", replay=False)
    )
    try:
        code = main(["print", str(tmp_path / "part.gcode"), "--profile", "paper-prototype"])
        err = capsys.readouterr().err
        assert code == 1 and "a print is running" in err and "--attach" in err
    finally:
        first.send(wire.Cancel())
        first.close()


def test_a_service_in_a_thread_ends_with_its_test(run_dir, monkeypatch, tmp_path):
    """What the tests' teardown does (tests/conftest.py): the print a test left running is
    cancelled and the service's threads are joined, so nothing of it logs after the test."""
    from tests.service import inprocess

    started = serve_in_thread(monkeypatch)
    client = attach(None, "left", replay=False)
    client.send(_start(tmp_path, speedup=2.0))
    _follow(client, until=lambda s: s.state is JobState.PRINTING)
    client.close()  # the test goes away with the print running
    service = started[0]
    threads = [t for t in inprocess._RUNNING if t.service is service]
    assert service.job_running and threads[0].thread.is_alive()
    inprocess.end_services()
    assert not service.job_running and not threads[0].thread.is_alive()
    assert inprocess._RUNNING == []
