"""The page's routes without a browser: the public page and its assets, the key on every
data route, the checks at the boundary (nothing moves when one fails), the event stream."""

from __future__ import annotations

import http.client
import json
import time

from cdprhost.server.web import ASSETS
from cdprhost.server.web_layers import gather, layer_doc
from tests.web.conftest import part


def request(server, method, path, body=None, key=True, headers=None):
    conn = http.client.HTTPConnection("127.0.0.1", server.thread.port, timeout=30)
    hdrs = dict(headers or {})
    if key:
        hdrs["X-Api-Key"] = server.key
    if body is not None:
        hdrs["Content-Type"] = "application/json"
        body = json.dumps(body).encode()
    try:
        conn.request(method, path, body, hdrs)
        reply = conn.getresponse()
        return reply.status, dict(reply.getheaders()), reply.read()
    finally:
        conn.close()


def test_the_page_and_its_assets_need_no_key_and_hold_nothing_of_the_printer(web_server):
    server = web_server()
    server.upload("secret_part.gcode", part())
    total = 0
    for route in ASSETS:
        status, headers, body = request(server, "GET", route, key=False)
        assert status == 200, route
        assert "default-src 'none'" in headers["content-security-policy"]
        assert headers["x-frame-options"] == "DENY"
        assert b"secret_part" not in body
        total += len(body)
        again = request(server, "GET", route, key=False, headers={"If-None-Match": headers["etag"]})
        assert again[0] == 304 and again[2] == b""
    assert total < 100_000
    assert request(server, "GET", "/static/../app.py", key=False)[0] == 401
    assert request(server, "GET", "/static/other.js", key=False)[0] == 401
    assert request(server, "POST", "/", key=False)[0] == 401


def test_controls_are_checked_before_anything_moves(web_server):
    server = web_server()
    for body, word in [
        ({"action": "launch"}, "action"),
        ({"action": "jog", "dx": 50}, "dx"),
        ({"action": "jog", "dz": "NaN"}, "dz"),
        ({"action": "jog", "dx": 1, "speed": 900}, "speed"),
        ([1, 2], "body"),
    ]:
        status, _, text = request(server, "POST", "/api/web/control", body)
        assert status == 400 and word in json.loads(text)["error"], (body, text)
    status, _, text = request(server, "POST", "/api/web/control", {"action": "jog"})
    assert status == 409 and "0 mm" in json.loads(text)["error"]
    assert server.links == []  # none of them even opened the device
    status, _, text = request(server, "POST", "/api/web/start", {"path": "../x.gcode"})
    assert status == 400
    status, _, text = request(server, "POST", "/api/web/start", {"path": "none.gcode"})
    assert status == 404 and server.links == []


def test_home_jog_heaters_off_and_e_stop_when_idle(web_server):
    server = web_server(speedup=None)
    status, _, text = request(server, "POST", "/api/web/control", {"action": "jog", "dx": 1})
    assert status == 409 and "home first" in json.loads(text)["error"]
    assert request(server, "POST", "/api/web/control", {"action": "home"})[0] == 200
    machine = server.device()
    before = list(map(float, machine.pos))
    assert request(server, "POST", "/api/web/control", {"action": "jog", "dz": -5})[0] == 200
    assert list(map(float, machine.pos)) != before
    status, _, text = request(server, "POST", "/api/web/control", {"action": "jog", "dz": 10})
    assert status == 409 and "workspace" in json.loads(text)["error"]  # above the top: refused
    moved = list(map(float, machine.pos))
    status, _, text = request(server, "POST", "/api/web/control", {"action": "jog", "dx": 10})
    for _ in range(100):  # sideways until the workspace refuses: nothing ever leaves it
        if status != 200:
            break
        status, _, text = request(server, "POST", "/api/web/control", {"action": "jog", "dx": 10})
    assert status == 409 and "workspace" in json.loads(text)["error"]
    assert list(map(float, machine.pos)) != moved
    assert request(server, "POST", "/api/web/control", {"action": "heaters_off"})[0] == 200
    assert request(server, "POST", "/api/web/control", {"action": "estop"})[0] == 200
    assert machine.estopped and machine.enabled_mask  # motors kept


def test_the_event_stream_pushes_the_state_document(web_server):
    server = web_server()
    conn = http.client.HTTPConnection("127.0.0.1", server.thread.port, timeout=30)
    conn.request("GET", "/api/web/events", headers={"X-Api-Key": server.key})
    reply = conn.getresponse()
    assert reply.status == 200 and reply.getheader("content-type").startswith("text/event-stream")
    lines = []
    end = time.monotonic() + 10
    while time.monotonic() < end:
        line = reply.fp.readline().decode()
        if line.startswith("data: "):
            lines.append(json.loads(line[6:]))
            break
    conn.close()
    doc = lines[0]
    assert doc["state"] == "idle" and doc["text"] == "Operational" and doc["history"] == []


def test_a_layer_document_is_compact_and_clamped(tmp_path):
    from cdprhost.motion.prepared import prepare
    from cdprhost.profile import load_profile

    path = tmp_path / "p.gcode"
    path.write_text(part(layers=4))
    moves = gather(prepare(path, load_profile("paper-prototype")).items())
    assert moves.layers >= 4
    doc = layer_doc(moves, 99)
    assert doc["layer"] == moves.layers - 1 and len(doc["xy"]) == 4 * len(doc["line"]) > 0
    assert all(isinstance(v, int) for v in doc["xy"])
    box = doc["box"]
    assert box[2] - box[0] > 19 and box[3] - box[1] > 19  # the 20 mm square


def test_a_camera_that_gives_no_picture_is_said_and_without_one_404(web_server, tmp_path):
    from cdprhost.server.web_camera import CameraSnapshot

    class Dead:
        def read(self):
            return False, None

        def release(self):
            pass

    server = web_server(camera=CameraSnapshot("0", open_capture=lambda spec: Dead()))
    status, _, text = request(server, "GET", "/api/web/camera")
    assert status == 503 and "no picture" in json.loads(text)["error"]
    assert request(server, "GET", "/api/web/camera", key=False)[0] == 401
    plain = web_server()
    assert request(plain, "GET", "/api/web/camera")[0] == 404
