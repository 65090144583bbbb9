"""The link's keep-alive: a thread that holds the session while nobody else pumps (idle,
paused, waiting for a heater; PROTOCOL.md 3.3), a part working on the link's core.

While the caller's thread pumps, it only naps. Otherwise it waits on the port without
the lock until the device sends something or half the keep-alive interval passes, then
pumps: a report, an error or an acknowledgement is read and answered at once rather than
left in the port's buffer until it looks lost (the device retransmits a report nobody
acknowledged; a clean idle link must retransmit nothing). When it sends a keep-alive it
waits for the acknowledgement. It never renews the heater lease: only the caller's calls
do, so a wedged job loses its heaters.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from cdprhost.link.core import LinkCore
from cdprhost.link.errors import LinkError
from cdprhost.link.tuning import SLICE_S


class KeepAlive:
    def __init__(self, core: LinkCore, wait_readable: Callable[[float], bool] | None):
        self.core = core
        self.wait_readable = wait_readable  # the transport's, if it has one
        self._stop: threading.Event | None = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="link-keepalive", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        if self._stop is not None:
            self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _loop(self) -> None:
        stop = self._stop
        assert stop is not None
        while not stop.is_set():
            self.step()

    def step(self) -> None:
        """One turn (without a thread, a caller drives the turns: tests, simulated time)."""
        core = self.core
        interval = core.keepalive_interval()
        thread = self._stop
        stop = thread or threading.Event()
        # nothing to keep alive once lost (a device stopped by a fault answers: kept)
        if core.pumping or core.fatal() is not None:
            stop.wait(SLICE_S if core.pumping else interval / 2)
            return
        readable = False
        if self.wait_readable is not None:
            readable = bool(self.wait_readable(interval / 2))
        else:
            stop.wait(interval / 2)
        if core.fatal() is not None or stop.is_set():
            return
        recent = core.t.now() - core.last_pump
        if readable and thread is not None and core.pumping:
            stop.wait(SLICE_S)  # the caller's thread is pumping: it reads them
            return
        if not readable and recent < interval / 2:
            return
        try:
            with core.locked():
                core.pump(0.0, fault_ok=True)
                end = core.t.now() + min(interval / 2, 4 * core.ep.sender.rto.rto)
                # the acknowledgements are awaited only while nobody else wants the link:
                # frames in flight may be a stream's, whose thread waits for the lock with
                # the report that gives it room (it held a feeding AVR 25-55 ms, its ring of
                # fast ramps about 30 ms, dry)
                while (
                    not core.ep.sender.idle() and core.t.now() < end and not core.others_waiting()
                ):
                    core.pump(min(SLICE_S, max(0.0, end - core.t.now())), fault_ok=True)
        except (LinkError, OSError):
            pass
