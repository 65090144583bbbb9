"""Run a SimDevice on a pseudo-terminal, in real time scaled by ``speedup``.

The slave side is put in raw mode and kept open by this process, so a host can
close and reopen the path at will (the device keeps running, and its output is
dropped like a UART's when nobody listens: the host flushes stale input on open).
What a host leaves unread is counted (:attr:`PtyServer.dropped_tx_bytes`) and said through
the device's notices (on ``cdprhost sim-device``'s stderr): when dropping begins, when the
host reads again (how much it lost meanwhile), and the total at :meth:`PtyServer.close`.
Faults (corruption, drops, duplication, latency, jitter) apply in both directions.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import time
import tty

from firmware_protocol.codes import BootCause
from firmware_protocol.device.faults import FaultSpec, FaultyChannel
from firmware_protocol.device.firmware import SimDevice

IDLE_WAIT_S = 0.05
RECORD_FLUSH_S = 0.25  # the streamed record reaches its file at least this often


class PtyServer:
    def __init__(self, device: SimDevice, faults: FaultSpec | None = None):
        self.device = device
        spec = faults or device.faults
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.rx = FaultyChannel(spec, seed_offset=1)
        self.tx = FaultyChannel(spec, seed_offset=2)
        self._t0 = time.monotonic()
        self._stop = False
        self._reset = False
        self._flushed = 0.0
        self.dropped_tx_bytes = 0  # device output the host did not read, in all
        self._dropping = 0  # of it, since the host last took a whole write

    def now(self) -> float:
        return time.monotonic() - self._t0

    def stop(self) -> None:
        self._stop = True

    def request_reset(self) -> None:
        """Pull the RESET pin at the next turn (safe from a signal handler): what opening the
        port of a Mega with auto-reset does (SIGUSR1 of ``cdprhost sim-device``)."""
        self._reset = True

    def write(self, data: bytes) -> int:
        """Hand ``data`` to the host; the bytes the pty took (the rest is dropped, counted
        and said: a host that does not read loses device output, never silently)."""
        try:
            n = os.write(self.master, data)
        except BlockingIOError:
            n = 0
        except OSError as exc:  # pragma: no cover - the slave is held open
            if exc.errno != errno.EIO:
                raise
            n = 0
        lost = len(data) - n
        if lost:
            if not self._dropping:
                self._notice("the host does not read the port: device output is dropped")
            self._dropping += lost
            self.dropped_tx_bytes += lost
        elif self._dropping:
            self._notice(
                f"the host reads the port again: {self._dropping} bytes of device output "
                f"were dropped meanwhile ({self.dropped_tx_bytes} in all)"
            )
            self._dropping = 0
        return n

    def _notice(self, text: str) -> None:
        if self.device.on_notice is not None:
            self.device.on_notice(text)

    def serve_step(self, max_wait: float = IDLE_WAIT_S) -> None:
        """One turn of the loop: wait for input or the next deadline, then run the device."""
        now = self.now()
        if self._reset:
            self._reset = False
            for frame in self.device.step(now, b""):  # executed up to the reset
                self.tx.send(frame, now)
            self.device.reboot(now, BootCause.EXTERNAL_RESET)
        times = [
            x
            for x in (
                self.device.next_deadline(now),
                self.rx.next_delivery(),
                self.tx.next_delivery(),
            )
            if x is not None
        ]
        wait = min([max_wait] + [max(0.0, x - now) for x in times])
        ready, _, _ = select.select([self.master], [], [], wait)
        now = self.now()
        if ready:
            try:
                data = os.read(self.master, 65536)
            except (BlockingIOError, InterruptedError):
                data = b""
            except OSError as exc:  # pragma: no cover - EIO only if the slave were closed
                if exc.errno != errno.EIO:
                    raise
                data = b""
            self.rx.send(data, now)
        incoming = self.rx.receive(now)
        deadline = self.device.next_deadline(now)
        if incoming or (deadline is not None and deadline <= now):
            for frame in self.device.step(now, incoming):
                self.tx.send(frame, now)
        out = self.tx.receive(now)
        if out:
            self.write(out)
        if now - self._flushed >= RECORD_FLUSH_S:
            self._flushed = now
            self.device.record.flush()

    def serve_forever(self) -> None:
        while not self._stop:
            self.serve_step()

    def close(self) -> None:
        if self.dropped_tx_bytes:
            self._notice(f"{self.dropped_tx_bytes} bytes of device output dropped in all")
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)
