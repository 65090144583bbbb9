"""Starting, pausing and cancelling over HTTP while a print runs (paced simulated device)."""

from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor

from tests.server.conftest import multipart, small_part

JSON = {"Content-Type": "application/json"}


def _upload(server, name, start=True, layers=3):
    fields = [("print", "true" if start else "false")]
    body, ctype = multipart(fields, (name, small_part(layers=layers).encode()))
    return server.request("POST", "/api/files/local", body, {"Content-Type": ctype})


def _command(server, **command):
    return server.request("POST", "/api/job", json.dumps(command).encode(), JSON)


def test_start_while_printing_is_409_and_pause_resume_cancel_work(make_server):
    server = make_server(speedup=10.0)  # a 40-layer part lasts ~15 s: cancelled long before
    assert _upload(server, "first.gcode", layers=40).status == 201
    server.wait_job(lambda j: j["state"] == "Printing")

    second = _upload(server, "second.gcode")
    assert second.status == 409
    assert "busy" in second.json()["error"] and "first.gcode" in second.json()["error"]
    assert "second.gcode" not in server.stored()
    assert server.printer.status().file.name == "first.gcode"
    assert len(server.links) == 1  # one device, one job

    stored_only = _upload(server, "later.gcode", start=False)  # storing is fine meanwhile
    assert stored_only.status == 201 and "later.gcode" in server.stored()
    assert _upload(server, "first.gcode", start=False).status == 409  # not over the printing file

    assert _command(server, command="pause", action="pause").status == 204
    server.wait_job(lambda j: j["state"] == "Paused")
    assert _command(server, command="start").status == 409  # a paused job is still a job
    assert _command(server, command="pause", action="resume").status == 204
    job = server.wait_job(lambda j: j["state"] == "Printing" and j["progress"]["filepos"])
    text, pos = small_part(layers=40).encode(), job["progress"]["filepos"]
    assert 0 < pos < len(text) and text[pos - 1 : pos] == b"\n"  # where a line starts

    assert _command(server, command="cancel").status == 204
    job = server.wait_job(lambda j: j["state"] == "Operational")
    assert job["progress"]["completion"] < 100
    assert server.printer.status().job.state.value == "cancelled"


def test_job_commands_with_nothing_to_do_are_409_and_bad_ones_400(make_server):
    server = make_server()
    assert _command(server, command="cancel").status == 409
    assert _command(server, command="pause", action="toggle").status == 409
    assert _command(server, command="start").status == 409  # nothing selected
    assert _command(server, command="restart").status == 400
    assert _command(server, command="pause", action="sideways").status == 400
    assert server.request("POST", "/api/job", b"not json", JSON).status == 400
    assert server.links == []


def test_select_then_start_command_prints(make_server):
    server = make_server()
    body, ctype = multipart([("select", "true")], ("sel.gcode", small_part().encode()))
    reply = server.request("POST", "/api/files/local", body, {"Content-Type": ctype})
    assert reply.status == 201 and reply.json()["effectiveSelect"] is True
    assert server.links == []
    assert _command(server, command="start").status == 204
    server.wait_job(lambda j: j["state"] == "Operational" and j["progress"]["completion"])
    assert server.printer.status().job.state.value == "done"


def test_version_job_and_listing_shapes(make_server):
    server = make_server()
    version = server.request("GET", "/api/version").json()
    assert version["text"].startswith("OctoPrint") and version["api"] and version["server"]
    idle = server.job()
    assert idle["state"] == "Operational" and idle["job"]["file"]["name"] is None
    assert set(idle["progress"]) >= {"completion", "printTime", "printTimeLeft", "filepos"}
    _upload(server, "listed.gcode", start=False)
    files = server.request("GET", "/api/files/local").json()
    assert [f["name"] for f in files["files"]] == ["listed.gcode"]
    assert files["files"][0]["type"] == "machinecode" and files["free"] > 0
    one = server.request("GET", "/api/files/local/listed.gcode")
    assert one.status == 200 and one.json()["size"] > 0
    assert server.request("GET", "/api/files/local/none.gcode").status == 404
    assert server.request("GET", "/api/files/local/..%2Fx.gcode").status in (400, 404)


def test_a_faulted_device_refuses_a_remote_start_with_the_fault_explained(make_server):
    server = make_server()
    assert _upload(server, "one.gcode").status == 201
    server.wait_job(lambda j: j["state"] == "Operational" and j["progress"]["completion"])
    link = server.links[0]
    link.emergency_stop(timeout=5.0)  # as M112 would: the device stays stopped by a fault
    executed = len(link.device.record)
    reply = _upload(server, "two.gcode")
    assert reply.status == 409
    text = reply.json()["error"]
    assert "fault" in text and "--clear-fault" in text and "nothing started" in text
    assert "two.gcode" not in server.stored()
    assert server.printer.status().file.name == "one.gcode"
    assert len(link.device.record) == executed  # nothing moved


def test_two_uploads_with_print_at_once_start_one_job(make_server):
    server = make_server(speedup=10.0)
    with ThreadPoolExecutor(2) as pool:
        replies = list(pool.map(lambda n: _upload(server, n, layers=40), ["a.gcode", "b.gcode"]))
    assert sorted(r.status for r in replies) == [201, 409]
    assert len(server.links) == 1 and len(server.stored()) == 1
    assert _command(server, command="cancel").status == 204
    server.wait_job(lambda j: j["state"] == "Operational")
