"""The keep-alive thread's rule for a report waiting in the port: it reads it at once unless
the caller's thread is inside a pump. A paused job polls the link every half second and
returns; a device report that arrives just after (HEALTH follows every STATUS) must not wait
a slice for a pump that is not coming, or it is retransmitted after the device's 20 ms floor
(issue 23: 24 device retransmissions in 60 s paused)."""

from __future__ import annotations

import contextlib
from types import SimpleNamespace

import pytest

from cdprhost.link.keepalive import KeepAlive
from cdprhost.link.tuning import SLICE_S


class _Clock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def now(self) -> float:
        return self.now_s


class _Core:
    """What the keep-alive uses of the link's core, recording its pumps."""

    def __init__(self, *, pumping: bool, since_pump_s: float) -> None:
        self.t = _Clock()
        self.pumping = pumping
        self.last_pump = self.t.now_s - since_pump_s
        self.dev = SimpleNamespace(failure=None)
        self.in_flight = False  # frames not acknowledged yet
        self.waiting = False  # another thread waits for the lock
        self.ep = SimpleNamespace(
            sender=SimpleNamespace(idle=lambda: not self.in_flight, rto=SimpleNamespace(rto=0.025))
        )
        self.pumps: list[float] = []

    def others_waiting(self) -> bool:
        return self.waiting

    def keepalive_interval(self) -> float:
        return 1.0

    def fatal(self):
        return self.dev.failure

    @contextlib.contextmanager
    def locked(self):
        yield

    def pump(self, timeout: float, *, fault_ok: bool = False) -> None:
        self.pumps.append(timeout)
        self.t.now_s += timeout


def _turn(core: _Core) -> None:
    keep = KeepAlive(core, wait_readable=lambda _timeout: True)  # a report is waiting
    keep._stop = _NoWait()  # as when its thread runs, without sleeping in the test
    keep.step()


class _NoWait:
    def is_set(self) -> bool:
        return False

    def wait(self, _timeout: float) -> bool:
        return False


@pytest.mark.parametrize("since_pump_s", [0.0, SLICE_S / 2, 0.2])
def test_a_waiting_report_is_read_at_once_when_nobody_pumps(since_pump_s):
    core = _Core(pumping=False, since_pump_s=since_pump_s)
    _turn(core)
    assert core.pumps and core.pumps[0] == 0.0  # read and acknowledged in this turn


def test_a_waiting_report_is_left_to_a_caller_inside_a_pump():
    core = _Core(pumping=True, since_pump_s=0.0)
    _turn(core)
    assert core.pumps == []


def test_frames_in_flight_are_awaited_while_nobody_else_wants_the_link():
    core = _Core(pumping=False, since_pump_s=0.2)
    core.in_flight = True  # its own keep-alive, say: it waits for the acknowledgement
    _turn(core)
    assert len(core.pumps) > 2 and sum(core.pumps) >= 4 * 0.025 - 1e-9


def test_a_stream_waiting_for_the_lock_is_not_held_for_its_own_frames():
    # the feed's frames are in flight and its thread waits for the lock (with the report
    # that gives it room): the keep-alive reads what came and lets go
    core = _Core(pumping=False, since_pump_s=0.2)
    core.in_flight = True
    core.waiting = True
    _turn(core)
    assert core.pumps == [0.0]
