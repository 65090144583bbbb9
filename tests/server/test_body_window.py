"""The slow-body rule on its own clock: a trickle is cut after the window of time the server
waits on it, even when many looks at it land while the app has not yet taken what came (a
busy print PC: the byte and the look arrive in the same turn of the event loop)."""

from __future__ import annotations

from cdprhost.server.connections import WATCH_PERIOD_S, BodyWindow


def _looks_until_cut(window: BodyWindow, waiting, bytes_per_look: int, looks: int) -> int | None:
    now = 0.0
    for i in range(looks):
        now += WATCH_PERIOD_S
        window.received(bytes_per_look)
        if window.too_slow(now, waiting(i)):
            return i
    return None


def test_a_trickle_is_cut_after_one_window_of_waiting():
    window = BodyWindow(window_s=1.0, min_bytes=1024, now=0.0)
    assert _looks_until_cut(window, lambda i: True, 3, 100) == 3  # 4 looks = 1 s


def test_looks_that_find_the_app_busy_pause_the_window_but_never_restart_it():
    # two looks in three find the byte not yet taken: under the old rule (restart) the
    # trickle was never cut; now only the waiting looks count
    window = BodyWindow(window_s=1.0, min_bytes=1024, now=0.0)
    cut = _looks_until_cut(window, lambda i: i % 3 == 2, 3, 100)
    assert cut is not None and cut == 3 * 4 - 1


def test_a_steady_body_is_never_cut_and_a_busy_app_holds_nothing_against_it():
    window = BodyWindow(window_s=1.0, min_bytes=1024, now=0.0)
    assert _looks_until_cut(window, lambda i: True, 400, 200) is None
    window = BodyWindow(window_s=1.0, min_bytes=1024, now=0.0)
    assert _looks_until_cut(window, lambda i: False, 0, 200) is None  # the app not reading


def test_restart_forgets_the_time_waited():
    window = BodyWindow(window_s=1.0, min_bytes=1024, now=0.0)
    assert not window.too_slow(0.75, True)
    window.restart(0.75)
    assert not window.too_slow(1.5, True)  # 0.75 s waited since the restart
    assert window.too_slow(1.75, True)
