"""``/api/printer`` and ``/api/settings``: what Cura's OctoPrint plugin and OctoPrint phone
apps read (the state, the heaters, the features), behind the same key as every route."""

from __future__ import annotations

import json
import subprocess
import time

import pytest

from tests.server.conftest import multipart, printed_to_the_end, small_part
from tests.server.test_slicer_clients import octoprint_executable


@pytest.mark.parametrize("path", ["/api/printer", "/api/settings"])
def test_the_routes_need_the_key(make_server, path):
    server = make_server()
    assert server.request("GET", path, key=None).status == 401
    assert server.request("GET", path, key="wrong").status == 403
    assert server.request("GET", path).status == 200


def test_printer_reports_the_print_and_its_heaters(make_server):
    server = make_server(speedup=20.0)
    idle = server.request("GET", "/api/printer").json()
    assert idle["state"]["text"] == "Operational" and idle["state"]["flags"]["ready"]
    assert idle["sd"] == {"ready": False}
    body, ctype = multipart([("print", "true")], ("part.gcode", small_part(20).encode()))
    assert server.request("POST", "/api/files/local", body, {"Content-Type": ctype}).status == 201
    server.wait_job(lambda j: j["state"] == "Printing")

    def heating(reply: dict) -> bool:
        t = reply.get("temperature", {})
        return "tool0" in t and t["tool0"]["target"] == 200.0 and t["bed"]["target"] == 40.0

    end = time.monotonic() + 60  # bounded: the job's first temperature reading
    while time.monotonic() < end:
        reply = server.request("GET", "/api/printer?history=true&limit=5").json()
        if heating(reply) or reply["state"]["text"] != "Printing":
            break
        time.sleep(0.05)
    assert heating(reply), reply
    flags = reply["state"]["flags"]
    assert flags["printing"] and flags["operational"] and not flags["ready"]
    assert 1 <= len(reply["temperature"]["history"]) <= 5
    assert {"time", "tool0", "bed"} <= set(reply["temperature"]["history"][-1])
    assert isinstance(reply["temperature"]["tool0"]["actual"], float)
    only_state = server.request("GET", "/api/printer?exclude=temperature,sd").json()
    assert set(only_state) == {"state"}
    server.wait_job(printed_to_the_end)
    after = server.request("GET", "/api/printer").json()
    assert after["state"]["text"] == "Operational" and after["state"]["flags"]["ready"]
    assert after["temperature"]["tool0"]["target"] == 0.0  # the file ended with M104 S0


def test_printer_refuses_a_bad_query(make_server):
    server = make_server()
    assert server.request("GET", "/api/printer?exclude=everything").status == 400
    assert server.request("GET", "/api/printer?history=true&limit=-1").status == 400


def test_settings_say_what_is_not_here(make_server):
    settings = make_server().request("GET", "/api/settings").json()
    assert settings["feature"]["sdSupport"] is False
    assert settings["webcam"]["webcamEnabled"] is False and settings["webcam"]["streamUrl"] == ""
    assert settings["api"]["allowCrossOrigin"] is False
    assert settings["temperature"]["profiles"][0]["extruder"] > 0


def _client_get(exe: str, server, tmp_path, path: str) -> dict:
    cmd = [exe, "--basedir", str(tmp_path / "octo"), "client", "--apikey", server.key]
    cmd += ["--host", "127.0.0.1", "--port", str(server.port), "get", path]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert "Status Code: 200" in out.stdout, out.stdout + out.stderr
    return dict(json.loads(out.stdout[out.stdout.index("{") :]))


def test_octoprint_client_reads_printer_and_settings(serve, tmp_path):
    """`octoprint client get /api/printer` and `/api/settings` on `cdprhost serve` (its device
    connected at start: the heaters are read without a job)."""
    exe = octoprint_executable()
    if exe is None:
        pytest.skip("OctoPrint is not installed (CI installs it in .venv-octoprint)")
    server = serve()
    printer = _client_get(exe, server, tmp_path, "/api/printer")
    assert printer["state"]["text"] == "Operational"
    assert printer["state"]["flags"]["operational"] and printer["state"]["flags"]["ready"]
    assert isinstance(printer["temperature"]["tool0"]["actual"], float)
    assert printer["temperature"]["bed"]["target"] == 0.0
    settings = _client_get(exe, server, tmp_path, "/api/settings")
    assert settings["feature"]["sdSupport"] is False and "webcam" in settings
    code, _ = server.stop()
    assert code == 0
