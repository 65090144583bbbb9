"""The web page in a real browser (chromium headless): the key, the pushed state, the
buttons and what the device does, upload by drag and drop, the graph and the layer view,
the phone's width, and the page's weight."""

from __future__ import annotations

import time
from typing import Any

import pytest

from tests.conftest import FIXTURE_GCODE
from tests.web.conftest import part, unlock

sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")

STATE_TEXT = "document.getElementById('state').textContent"
API_ROUTES = [
    ("GET", "/api/web/events", None),
    ("GET", "/api/job", None),
    ("GET", "/api/files", None),
    ("GET", "/api/web/layer?n=0", None),
    ("GET", "/api/web/camera", None),
    ("POST", "/api/web/control", {"action": "estop"}),
    ("POST", "/api/web/control", {"action": "home"}),
    ("POST", "/api/job", {"command": "cancel"}),
    ("POST", "/api/web/start", {"path": "part.gcode"}),
]
FETCH_ALL = """async ([routes, key]) => {
  const out = [];
  for (const [method, path, body] of routes) {
    const headers = {"Content-Type": "application/json"};
    if (key !== null) headers["X-Api-Key"] = key;
    const r = await fetch(path, {method, headers, body: body === null ? undefined : JSON.stringify(body)});
    out.push(r.status);
  }
  return out;
}"""


def drop_file(pg: Any, name: str, text: str) -> None:
    """Drag a file onto the drop zone, as a person drops one from the desktop."""
    transfer = pg.evaluate_handle(
        """([name, text]) => { const dt = new DataTransfer();
           dt.items.add(new File([text], name, {type: "text/plain"})); return dt; }""",
        [name, text],
    )
    pg.dispatch_event("#drop", "dragover", {"dataTransfer": transfer})
    pg.dispatch_event("#drop", "drop", {"dataTransfer": transfer})


def test_the_page_unlocks_with_the_key_and_shows_the_idle_printer(web_server, page):
    server = web_server()
    unlock(page, server)
    page.wait_for_function(f"{STATE_TEXT}.startsWith('idle')")
    assert page.is_visible("#printer") and not page.is_visible("#login")
    assert page.evaluate("localStorage.getItem('cdprhost.apikey')") == server.key
    page.reload()  # entered once: kept in the browser
    page.wait_for_function(f"{STATE_TEXT}.startsWith('idle')")
    assert not page.is_visible("#login")


def test_without_the_key_nothing_of_the_printer_shows_and_every_action_is_refused(web_server, page):
    server = web_server()
    server.upload("part.gcode", part())
    replies: list[tuple[str, int]] = []
    page.on("response", lambda r: replies.append((r.url, r.status)))
    page.goto(server.url + "/")
    page.wait_for_selector("#login", state="visible")
    assert not page.is_visible("#printer")
    assert "part.gcode" not in page.content()
    api = [(u, s) for u, s in replies if "/api/" in u]
    assert all(s == 401 for _, s in api), api
    assert page.evaluate(FETCH_ALL, [API_ROUTES, None]) == [401] * len(API_ROUTES)
    assert page.evaluate(FETCH_ALL, [API_ROUTES, "0" * 32]) == [403] * len(API_ROUTES)
    upload = """async (key) => { const form = new FormData();
      form.append("file", new File(["G28\\n"], "sneaky.gcode")); form.append("print", "true");
      const headers = key ? {"X-Api-Key": key} : {};
      return (await fetch("/api/files/local", {method: "POST", headers, body: form})).status; }"""
    assert page.evaluate(upload, None) == 401
    assert page.evaluate(upload, "0" * 32) == 403
    assert not (server.uploads / "sneaky.gcode").exists()
    assert server.links == []  # the device was never even opened
    # a wrong key entered in the page: refused, still nothing shown
    page.fill("#key", "0" * 32)
    page.click("#key-form button[type=submit]")
    page.wait_for_function("document.getElementById('login-error').textContent.includes('refused')")
    assert not page.is_visible("#printer") and server.links == []
    # the right key, then "Forget key": the printer's data leaves the page
    page.fill("#key", server.key)
    page.click("#key-form button[type=submit]")
    page.wait_for_function(f"{STATE_TEXT}.startsWith('idle')")
    page.wait_for_function("document.getElementById('files').textContent.includes('part.gcode')")
    page.click("#forget")
    assert not page.is_visible("#printer")
    assert page.text_content("#state") == "" and "part.gcode" not in page.inner_text("body")


def test_state_changes_reach_the_page_within_half_a_second(web_server, page):
    """The device pauses and resumes (asked by the API, as a slicer or the TUI would): each
    state is drawn in the page within 0.5 s of the printer's own event."""
    server = web_server(speedup=2.0)
    unlock(page, server)
    no_wait = part(layers=12).replace("M109 S200\n", "")  # prints at once, no heating wait
    assert server.upload("long.gcode", no_wait, start=True) == 201
    server.wait_state("printing")
    late: dict[str, float] = {}
    for action, state in (("pause", "paused"), ("resume", "printing")):
        if state == "printing":
            time.sleep(0.3)  # so that the page's last "printing" is this one, not the first
        assert server.job_command({"command": "pause", "action": action}) == 204
        server.wait_state(state)
        page.wait_for_function(
            f"window.cdpr.doc.state === '{state}'"
            f" && window.cdpr.seen['{state}'] >= {1000 * server.reached[state] - 50}"
        )
        late[state] = page.evaluate(f"window.cdpr.seen['{state}']") / 1000.0 - server.reached[state]
    assert all(s < 0.5 for s in late.values()), f"seen in the page after the device (s): {late}"


def test_upload_by_drop_start_and_the_buttons_pause_resume_cancel(web_server, page):
    server = web_server(speedup=2.0)
    unlock(page, server)
    page.check("#upload-start")
    drop_file(page, "dropped.gcode", part(layers=12).replace("M109 S200\n", ""))
    server.wait_state("heating", "printing")  # started by the drop
    server.wait_state("printing")  # heated: pausing now stops the motion itself
    assert (server.uploads / "dropped.gcode").is_file()
    assert server.printer.status().file.name == "dropped.gcode"
    page.wait_for_function(
        "document.getElementById('file').textContent === 'dropped.gcode'"
        " && !document.getElementById('pause').disabled"
    )
    page.click("#pause")
    server.wait_state("paused")
    machine = server.device()
    held = machine.segments_done
    time.sleep(0.3)
    assert machine.segments_done == held  # the device stands still while paused
    page.wait_for_function("!document.getElementById('resume').disabled")
    page.click("#resume")
    server.wait_state("printing", "heating")
    end = time.monotonic() + 20
    while machine.segments_done == held and time.monotonic() < end:
        time.sleep(0.05)
    assert machine.segments_done > held  # and moves on once resumed
    page.wait_for_function("!document.getElementById('pause').disabled")
    page.click("#cancel")  # its confirm() is accepted
    server.wait_state("cancelled")
    page.wait_for_function(f"{STATE_TEXT}.startsWith('cancelled')")
    page.wait_for_function("document.getElementById('history').textContent.includes('cancelled')")
    # the history names the resume point the cancel saved
    page.wait_for_function(
        "document.getElementById('history').textContent.includes('resume point: line')"
    )


def test_a_stored_file_starts_from_the_list_and_the_e_stop_keeps_the_motors(web_server, page):
    server = web_server(speedup=10.0)
    server.upload("listed.gcode", part(layers=30))
    unlock(page, server)
    page.click("#files button[data-path='listed.gcode']")
    server.wait_state("printing")
    page.wait_for_function(f"{STATE_TEXT}.startsWith('printing')")
    page.click("#estop")
    server.wait_state("failed")
    machine = server.device()
    assert machine.estopped
    assert machine.enabled_mask  # motors kept: the effector does not drop
    page.wait_for_function(f"{STATE_TEXT}.startsWith('failed')")


def test_the_temperature_graph_and_the_layer_view_follow_the_print(web_server, page):
    server = web_server(speedup=10.0)
    unlock(page, server)
    assert server.upload("layers.gcode", part(layers=30), start=True) == 201
    page.wait_for_function("window.cdpr.doc.graph.length >= 2")
    first_graph = page.evaluate("[window.cdpr.graphDraws, window.cdpr.doc.graph.length]")
    page.wait_for_function("window.cdpr.layer !== null")
    first_layer = page.evaluate("window.cdpr.layer.layer")
    page.wait_for_function(f"window.cdpr.layer && window.cdpr.layer.layer > {first_layer}")
    page.wait_for_function(f"window.cdpr.graphDraws > {first_graph[0]}")
    assert page.evaluate("window.cdpr.doc.graph.length") > first_graph[1]
    assert page.evaluate("window.cdpr.layer.xy.length") > 0
    lit = """(id) => { const c = document.getElementById(id);
      const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let n = 0; for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n; }"""
    assert page.evaluate(lit, "graph") > 100
    assert page.evaluate(lit, "layer-view") > 100
    assert page.text_content("#layer-title").startswith(
        str(page.evaluate("window.cdpr.layer.layer") + 1)
    )


def test_on_a_phone_nothing_scrolls_sideways(web_server, browser):
    server = web_server(speedup=10.0)
    context = browser.new_context(
        viewport={"width": 390, "height": 844},
        device_scale_factor=2,
        is_mobile=True,
        has_touch=True,
        bypass_csp=True,
    )
    try:
        pg = context.new_page()
        pg.set_default_timeout(20_000)
        pg.goto(server.url + "/")
        wide = "document.documentElement.scrollWidth - window.innerWidth"
        assert pg.evaluate(wide) <= 0  # the key form
        pg.fill("#key", server.key)
        pg.click("#key-form button[type=submit]")
        name = "a_very_long_file_name_that_a_slicer_would_make_for_a_part_" + "x" * 60 + ".gcode"
        assert server.upload(name, part(layers=20), start=True) == 201
        pg.wait_for_function("window.cdpr.layer !== null && window.cdpr.doc.graph.length > 1")
        pg.wait_for_function("document.getElementById('files').textContent.includes('very_long')")
        assert pg.evaluate(wide) <= 0
        assert pg.evaluate("document.body.scrollWidth") <= 390
    finally:
        context.close()


def test_the_page_weighs_under_300_kb(web_server, page):
    """Everything the page loads (assets, file list, the layer view of a real sliced part)."""
    if not FIXTURE_GCODE.is_file():
        pytest.skip(f"{FIXTURE_GCODE} is missing (the shared reference material)")
    server = web_server(speedup=50.0)
    sizes: dict[str, int] = {}

    def count(response: Any) -> None:
        if "/api/web/events" in response.url:
            return
        try:
            sizes[response.url] = sizes.get(response.url, 0) + len(response.body())
        except sync_api.Error:  # a reply without a body (304)
            sizes[response.url] = sizes.get(response.url, 0)

    page.on("response", count)
    unlock(page, server)
    assert server.upload("real.gcode", FIXTURE_GCODE.read_text(), start=True) == 201
    page.wait_for_function("window.cdpr.layer !== null && window.cdpr.layer.xy.length > 1000")
    page.wait_for_timeout(300)  # the response events of the page's last requests are handled
    assert any(u.endswith("/static/app.js") for u in sizes), sizes
    assert any("/api/web/layer" in u for u in sizes), sizes
    assert sum(sizes.values()) <= 300_000, sizes


def test_a_configured_camera_gives_a_snapshot_in_the_page(web_server, page, tmp_path):
    import cv2
    import numpy as np

    from cdprhost.server.web_camera import CameraSnapshot

    picture = np.zeros((120, 160, 3), np.uint8)
    picture[30:90, 40:120] = (0, 200, 255)
    cv2.imwrite(str(tmp_path / "camera.png"), picture)
    server = web_server(camera=CameraSnapshot(str(tmp_path / "camera.png")))
    unlock(page, server)
    page.wait_for_selector("#camera-card", state="visible")
    page.click("#snap")
    page.wait_for_function("document.getElementById('camera').naturalWidth === 160")


def test_without_a_camera_the_page_shows_no_camera(web_server, page):
    server = web_server()
    unlock(page, server)
    assert not page.is_visible("#camera-card")
