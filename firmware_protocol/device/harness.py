"""In-process bench: a SimDevice behind two fault-injecting channels on one clock.

The host side sees a byte transport (``write``, ``read(timeout)``, ``now``,
``close``). Time is virtual: ``read`` jumps the clock from event to event (byte
deliveries, device deadlines) and never sleeps, unless ``pace`` is given, in which
case virtual time runs at most ``pace`` times faster than the wall clock.
"""

from __future__ import annotations

import math
import time

from firmware_protocol.device.faults import FaultSpec, FaultyChannel
from firmware_protocol.device.firmware import SimDevice

DEFAULT_BAUD = 250_000


class VirtualBench:
    name = "embedded simulated device"

    def __init__(
        self,
        device: SimDevice | None = None,
        *,
        faults: FaultSpec | None = None,
        baud: int | None = DEFAULT_BAUD,
        pace: float | None = None,
    ):
        self.device = device or SimDevice(faults=faults)
        spec = faults or self.device.faults
        self.to_device = FaultyChannel(spec, seed_offset=1, baud=baud)
        self.to_host = FaultyChannel(spec, seed_offset=2, baud=baud)
        self.t = 0.0
        self.pace = pace
        self._wall0 = time.monotonic()
        self._host_rx = bytearray()
        self.closed = False

    # ------------------------------------------------------------------ transport API

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> None:
        self.to_device.send(bytes(data), self.t)

    def read(self, timeout: float) -> bytes:
        target = self.t + max(0.0, timeout)
        if timeout > 0 and target <= self.t:  # below float resolution: still move on
            target = math.nextafter(self.t, math.inf)
        self.run_until(target, stop_on_data=True)
        out = bytes(self._host_rx)
        self._host_rx.clear()
        return out

    def wait_readable(self, timeout: float) -> bool:
        """Run the device until bytes reach the host (True) or ``timeout`` s pass (False);
        the bytes stay for ``read``."""
        self.run_until(self.t + max(0.0, timeout), stop_on_data=True)
        return bool(self._host_rx)

    def close(self) -> None:
        self.closed = True

    # ------------------------------------------------------------------ simulation

    def _settle(self) -> float | None:
        """Run everything due now; returns the device's next deadline."""
        t = self.t
        deadline = None
        for _ in range(64):
            data = self.to_device.receive(t)
            deadline = self.device.next_deadline(t)
            if not data and (deadline is None or deadline > t):
                break
            for frame in self.device.step(t, data):
                self.to_host.send(frame, t)
        self._host_rx += self.to_host.receive(t)
        return deadline

    def _set_clock(self, t: float) -> None:
        if self.pace:
            now = time.monotonic()
            ahead = self._wall0 + t / self.pace - now
            if ahead > 0:
                time.sleep(ahead)
            elif ahead < -0.05:  # virtual time stood still (nobody pumped): no catch-up burst
                self._wall0 -= ahead + 0.05
        self.t = max(self.t, t)

    def run_until(self, target: float, stop_on_data: bool = False) -> None:
        """Advance the clock to ``target`` (or until bytes reach the host if ``stop_on_data``)."""
        stuck = 0
        while True:
            deadline = self._settle()
            if stop_on_data and self._host_rx:
                return
            times = [
                x
                for x in (self.to_host.next_delivery(), self.to_device.next_delivery(), deadline)
                if x is not None
            ]
            nxt = min(times, default=math.inf)
            if nxt > target:
                self._set_clock(target)
                self._settle()
                return
            if nxt <= self.t:
                stuck += 1
                nxt = self.t + (1e-6 if stuck > 8 else 0.0)
            else:
                stuck = 0
            self._set_clock(nxt)
