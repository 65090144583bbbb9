"""The device's clock rate, measured against the host's (PROTOCOL.md section 3.2).

FLOW and IDENT carry the device's free-running clock (u32 ticks of ``clock_hz``,
wrapping) as of when they were sent; both are never retransmitted, so the clock is
fresh (a STATUS may be a retransmission carrying an old clock: not used). The host
unwraps it and estimates how many device ticks pass per host second from the oldest
and newest samples of a sliding window, as Klipper's clock synchronisation does. A crystal gives ``clock_hz`` to within 100 ppm; a simulated
device running X times faster is measured as ``X * clock_hz``.
"""

from __future__ import annotations

from collections import deque

WRAP = 1 << 32
WINDOW_S = 30.0  # samples older than this are dropped
MIN_SPAN_S = 0.05  # no estimate from samples closer together than this


class ClockSync:
    def __init__(self, nominal_hz: int):
        self.nominal_hz = nominal_hz
        self._samples: deque[tuple[float, int]] = deque()
        self._last_raw: int | None = None
        self._base = 0

    def add(self, host_t: float, raw_clock: int) -> None:
        """A clock value received at host time ``host_t``."""
        if self._last_raw is not None and raw_clock < self._last_raw:
            if self._last_raw - raw_clock > WRAP // 2:
                self._base += WRAP  # wrapped
            else:
                return  # a stale report (older than the last): ignore
        self._last_raw = raw_clock
        clock = self._base + raw_clock
        samples = self._samples
        if samples and clock < samples[-1][1]:
            return
        samples.append((host_t, clock))
        while len(samples) > 2 and host_t - samples[1][0] > WINDOW_S:
            samples.popleft()

    @property
    def span_s(self) -> float:
        s = self._samples
        return s[-1][0] - s[0][0] if len(s) >= 2 else 0.0

    @property
    def known(self) -> bool:
        return self.span_s >= MIN_SPAN_S

    def rate(self) -> float:
        """Device ticks per host second (the nominal clock until enough samples)."""
        s = self._samples
        if not self.known:
            return float(self.nominal_hz)
        (t0, c0), (t1, c1) = s[0], s[-1]
        return max((c1 - c0) / (t1 - t0), 1e-9)
