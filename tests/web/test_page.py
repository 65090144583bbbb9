"""The web page in a real browser (chromium headless): the key, the pushed state, the
buttons and what the device does, upload by drag and drop, the graph and the layer view,
the phone's width, and the page's weight."""

from __future__ import annotations

from tests.web.conftest import unlock

STATE_TEXT = "document.getElementById('state').textContent"


def test_the_page_unlocks_with_the_key_and_shows_the_idle_printer(web_server, page):
    server = web_server()
    unlock(page, server)
    page.wait_for_function(f"{STATE_TEXT}.startsWith('idle')")
    assert page.is_visible("#printer") and not page.is_visible("#login")
    assert page.evaluate("localStorage.getItem('cdprhost.apikey')") == server.key
    page.reload()  # entered once: kept in the browser
    page.wait_for_function(f"{STATE_TEXT}.startsWith('idle')")
    assert not page.is_visible("#login")
