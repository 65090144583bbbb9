"""Temperatures (and the rest of the device's status) kept fresh in every state.

A print job reads the status while it streams; between jobs, paused, after a cancel or
an e-stop nobody did, and screens showed the last value for minutes. A
:class:`StatusPoll` owns one background thread per link: every ``every_s`` it looks at the
link's latest status (no I/O) and, when that is older than ``every_s``, asks the device
for a new one without waiting (the reply arrives while anyone pumps the link, the poll
included). Subscribers get a :class:`Reading` each time: the status and its age, marked
stale past ``stale_s`` or when the link fails (a link that stopped answering, a closed
port: the last status is history, and ``error`` says why). A device stopped by a fault
(an e-stop, its watchdog) still answers: its readings stay fresh (the nozzle is seen
cooling) and ``error`` names the fault.

Thread-safe; never raises into its thread (a failing link only makes readings stale).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

from cdprhost.link.errors import LinkError
from cdprhost.link.events import DeviceStatus
from cdprhost.link.host_link import HostLink
from firmware_protocol.codes import Flag

log = logging.getLogger(__name__)

EVERY_S = 1.0
STALE_S = 3.0


@dataclass(frozen=True)
class Reading:
    status: DeviceStatus | None  # None: no status yet
    age_s: float  # link seconds since it was received (inf without one)
    stale: bool
    error: str = ""  # why the link gives no fresh status (a fault, a closed port)

    # the job's Temperatures event from a reading: cdprhost.job.state.temperatures_of


class StatusPoll:
    def __init__(self, link: HostLink, every_s: float = EVERY_S, stale_s: float = STALE_S):
        self.link = link
        self.every_s = float(every_s)
        self.stale_s = float(stale_s)
        self._subs: list[Callable[[Reading], None]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error = ""

    def subscribe(self, fn: Callable[[Reading], None]) -> Callable[[], None]:
        """``fn`` gets every reading (in the poll's thread); returns the unsubscribe call."""
        with self._lock:
            self._subs.append(fn)

        def unsubscribe() -> None:
            with self._lock:
                if fn in self._subs:
                    self._subs.remove(fn)

        return unsubscribe

    def reading(self) -> Reading:
        """The latest status and its age (no I/O)."""
        st = self.link.status()
        flags = self.link.progress.flags
        fault = (
            "the device is e-stopped"
            if flags & Flag.ESTOP
            else "the device reports a fault"
            if flags & Flag.FAULT
            else ""
        )
        error = self._error or fault
        if st is None:
            return Reading(None, float("inf"), True, error)
        try:
            age = max(0.0, self.link.now() - st.received_at)
        except (LinkError, OSError):
            age = float("inf")
        return Reading(st, age, age > self.stale_s or bool(self._error), error)

    def tick(self) -> Reading:
        """One poll: ask for a status when the latest is old, then tell the subscribers."""
        if self.reading().age_s > self.every_s or self._error:
            try:
                self.link.ask_status()
                self.link.poll(0.0, fault_ok=True)  # a faulted device answers too
                self._error = ""
            except (LinkError, OSError) as exc:  # closed or failed: readings go stale
                log.debug("status poll: %s", exc)
                self._error = str(exc) or type(exc).__name__
        now = self.reading()
        with self._lock:
            subs = list(self._subs)
        for fn in subs:
            try:
                fn(now)
            except Exception:
                log.exception("status poll subscriber failed")
        return now

    def start(self) -> StatusPoll:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="status-poll", daemon=True)
            self._thread.start()
        return self

    def _loop(self) -> None:
        while not self._stop.wait(self.every_s):
            self.tick()

    def stop(self) -> None:
        """Stop polling (before the link is closed)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self._thread = None
