"""Run a SimDevice on a pseudo-terminal, in real time scaled by ``speedup``.

The slave side is put in raw mode and kept open by this process, so a host can
close and reopen the path at will (the device keeps running, and its output is
dropped like a UART's when nobody listens: the host flushes stale input on open).
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
        self.dropped_tx_bytes = 0

    def now(self) -> float:
        return time.monotonic() - self._t0

    def stop(self) -> None:
        self._stop = True

    def request_reset(self) -> None:
        """Pull the RESET pin at the next turn (safe from a signal handler): what opening the
        port of a Mega with auto-reset does (SIGUSR1 of ``cdprhost sim-device``)."""
        self._reset = True

    def _write(self, data: bytes) -> None:
        try:
            n = os.write(self.master, data)
        except BlockingIOError:
            n = 0
        except OSError as exc:  # pragma: no cover - the slave is held open
            if exc.errno != errno.EIO:
                raise
            n = 0
        self.dropped_tx_bytes += len(data) - n

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
            self._write(out)
        if now - self._flushed >= RECORD_FLUSH_S:
            self._flushed = now
            self.device.record.flush()

    def serve_forever(self) -> None:
        while not self._stop:
            self.serve_step()

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)
