"""The printer service's wire and journal: what a client sends is validated with the
field named; every job event crosses intact; a late client's replay folds to the state
that every event folds to."""

from __future__ import annotations

import pytest

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import (
    Failure,
    JobSnapshot,
    JobState,
    LinkHealth,
    Notice,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
    reduce,
)
from cdprhost.profile import load_profile
from cdprhost.service import wire
from cdprhost.service.journal import Journal
from cdprhost.sim.embedded import open_embedded
from tests.e2e.processes import square_part


@pytest.mark.parametrize(
    ("line", "where"),
    [
        (b'{"op": "hello", "v": 1}', "hello.key"),
        (b'{"op": "launch"}', "op"),
        (b'{"op": "cancel", "reason": 5}', "cancel.reason"),
        (b'{"op": "pause", "extra": 1}', "pause.extra"),
        (
            b'{"op": "start", "job": {"gcode": "", "profile": {}, "log_path": "x"}}',
            "start.job.gcode",
        ),
        (b"not json", "message"),
    ],
)
def test_a_bad_request_is_refused_naming_the_field(line, where):
    with pytest.raises(wire.WireError) as err:
        wire.decode_request(line)
    assert str(err.value).startswith(where), err.value


def test_an_overlong_line_is_refused_before_parsing():
    with pytest.raises(wire.WireError, match="bytes"):
        wire.decode_request(b"{" + b" " * wire.MAX_LINE + b"}")


EVENTS = [
    StateChanged(JobState.PREFLIGHT, "part.gcode"),
    Planned(12, 400, 93.5, 812.0, segments=9, done_s=1.5),
    Progress(10, 44, 2, 3.25, (1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0), (1, 2, 3, 4)),
    Temperatures(200.5, 60.0, 210.0, 60.0, 0.4),
    LinkHealth(3, 1, 2),
    Failure("link lost", 44, 2, (1.0, 2.0, 3.0), "/x/part.resume.json"),
    Notice("heaters on"),
]


@pytest.mark.parametrize("event", EVENTS, ids=lambda e: type(e).__name__)
def test_every_event_crosses_the_wire_intact(event):
    line = wire.encode(wire.EventMsg(event=wire.event_to_json(event)))
    message = wire.decode_reply(line)
    assert wire.event_from_json(message.event) == event


def test_an_unknown_event_is_refused():
    with pytest.raises(wire.WireError, match="unknown event"):
        wire.event_from_json({"type": "Explosion"})
    with pytest.raises(wire.WireError, match="unknown state"):
        wire.event_from_json({"type": "StateChanged", "state": "flying"})


def test_a_late_clients_replay_folds_to_the_same_state(tmp_path):
    """A real job's events: folding the journal's replay gives the snapshot that folding
    every event gives (but the device times temperatures are drawn against)."""
    events: list = []
    job = PrintJob(
        square_part(tmp_path / "part.gcode", layers=3),
        load_profile("paper-prototype"),
        open_embedded,
        PrintOptions(resume_dir=tmp_path),
        on_event=events.append,
    )
    assert job.run().status == "completed"
    journal = Journal()
    full = JobSnapshot()
    for event in events:
        journal.add(event)
        full = reduce(full, event)
    replayed = JobSnapshot()
    for event in journal.replay():
        replayed = reduce(replayed, wire.event_from_json(wire.event_to_json(event)))
    assert journal.count == len(events) > len(journal.replay())
    assert replayed.state is JobState.DONE and replayed.segments_done > 0
    assert [t[1:] for t in replayed.temperature_history] == [
        t[1:] for t in full.temperature_history
    ]
    # the machine time is a sum of the progress steps, added in another grouping by a replay
    # that keeps only the last of a run of progress events: equal to the last bits
    assert replayed.machine_time_s == pytest.approx(full.machine_time_s, rel=1e-12)
    drop = {"temperature_history": (), "machine_time_s": 0.0}
    assert replayed.__class__(**{**replayed.__dict__, **drop}) == (
        full.__class__(**{**full.__dict__, **drop})
    )


@pytest.mark.parametrize(
    ("line", "where"),
    [
        (b'{"op": "move", "id": 1, "target": [1, 2]}', "move.target"),
        (b'{"op": "move", "id": 1, "target": [1, 2, 3], "feed_mm_s": -1}', "move.feed_mm_s"),
        (b'{"op": "heaters", "id": 1, "hotend": -5}', "heaters.hotend"),
        (b'{"op": "connect", "id": 1}', "connect.profile"),
        (b'{"op": "home", "id": 1, "speed": 3}', "home.speed"),
    ],
)
def test_a_bad_device_request_is_refused_naming_the_field(line, where):
    with pytest.raises(wire.WireError, match=where.replace(".", r"\.")):
        wire.decode_request(line)


def test_the_device_session_messages_cross_the_wire():
    state = wire.DeviceState(
        steps=(1, 2, 3, 4),
        hotend_c=20.5,
        bed_c=21.0,
        hotend_target_c=0.0,
        bed_target_c=0.0,
        enabled_mask=7,
        homed_mask=7,
        queue_free=128,
        fault="the device is stopped by a fault (ESTOP)",
        clearable=True,
    )
    for message in (
        wire.Answer(id=3, ok=True, identity={"axes": 4}, status=state, confirmed=True),
        wire.DeviceMsg(connected=True, status=state, health=wire.Health(retransmits=2)),
        wire.Note(kind="error", text="device error X"),
        wire.JobInfo(gcode="/a/part.gcode", state="printing", started_at=1.5),
    ):
        assert wire.decode_reply(wire.encode(message)) == message
    for request in (wire.MoveTo(id=2, target=(1.0, 2.0, 3.0)), wire.Heaters(id=1, bed=60.0)):
        assert wire.decode_request(wire.encode(request)) == request


def test_a_client_skips_a_message_it_does_not_know_and_reads_on():
    import socket
    import threading
    from pathlib import Path

    from cdprhost.service.client import ServiceClient
    from cdprhost.service.paths import ServiceFiles

    ours, theirs = socket.socketpair()
    client = ServiceClient(ours, ServiceFiles(Path("/nonexistent"), "x"))
    threading.Thread(target=client._read_loop, daemon=True).start()
    theirs.sendall(b'{"msg": "speed", "percent": 120}\n')  # a newer service's message
    theirs.sendall(b'{"msg": "note", "text": "still here", "since": 2}\n')
    theirs.close()
    first = client.inbox.get(timeout=5)
    assert isinstance(first, wire.Note) and first.text == "still here"
    assert client.inbox.get(timeout=5) is None  # then the end, not a broken stream
    ours.close()
