"""The device's clock rate, measured against the host's (PROTOCOL.md section 3.2).

FLOW and IDENT carry the device's free-running clock (u32 ticks of ``clock_hz``,
wrapping) as of when they were sent; both are never retransmitted, so the clock is
fresh (a STATUS may be a retransmission carrying an old clock: not used). The host
unwraps it and estimates how many device ticks pass per host second from the oldest
and newest samples of a sliding window, as Klipper's clock synchronisation does. A crystal gives ``clock_hz`` to within 100 ppm; a simulated
device running X times faster is measured as ``X * clock_hz``.

A sample is received some time after it was sent: a few ms on a quiet line, much more
when the host was busy and the report waited in the port's buffer. A report read late
must not pass for a fresh one (the host would count the device's buffered motion from
the wrong moment and think it holds more than it does, just when a busy host needs it to
hold enough). So the sync keeps the quickest sample lately (the least delay between send
and receipt, as NTP's and Klipper's clock filters do) and :meth:`add` gives each sample's
send time as that sample's receipt plus the device time between them, which is earlier
than its own receipt when it arrived late. The quickest sample is forgotten slowly
(:data:`QUICK_LEAK`), so that an error in the rate cannot pile up.
"""

from __future__ import annotations

from collections import deque

WRAP = 1 << 32
WINDOW_S = 30.0  # samples older than this are dropped
MIN_SPAN_S = 0.05  # no estimate from samples closer together than this
QUICK_LEAK = 0.002  # host seconds a second by which the quickest sample's delay is forgotten


class ClockSync:
    def __init__(self, nominal_hz: int):
        self.nominal_hz = nominal_hz
        self._samples: deque[tuple[float, int]] = deque()
        self._last_raw: int | None = None
        self._base = 0
        self._quick: tuple[float, int] | None = None  # the quickest sample lately
        self._measured: float | None = None  # the rate, once the samples span MIN_SPAN_S

    def add(self, host_t: float, raw_clock: int) -> float:
        """A clock value received at host time ``host_t``; returns when it was sent, in host
        time, as far as the quickest sample lately tells (``host_t`` when it cannot)."""
        if self._last_raw is not None and raw_clock < self._last_raw:
            if self._last_raw - raw_clock > WRAP // 2:
                self._base += WRAP  # wrapped
            else:
                return host_t  # a stale report (older than the last): ignore
        self._last_raw = raw_clock
        clock = self._base + raw_clock
        samples = self._samples
        if samples and clock < samples[-1][1]:
            return host_t
        sent = host_t
        quick = self._quick
        rate = self._measured  # (of the samples before this one)
        if quick is not None and rate is not None:
            q_t, q_clock = quick
            sent = min(host_t, q_t + (clock - q_clock) / rate + QUICK_LEAK * (host_t - q_t))
        if sent >= host_t or quick is None:  # as quick as that one, or quicker: the reference
            self._quick = (host_t, clock)
        # (the rate stays on the receipts: dated by a rate, the samples would bend it)
        samples.append((host_t, clock))
        while len(samples) > 2 and host_t - samples[1][0] > WINDOW_S:
            samples.popleft()
        (t0, c0), (t1, c1) = samples[0], samples[-1]
        if t1 - t0 >= MIN_SPAN_S:
            self._measured = max((c1 - c0) / (t1 - t0), 1e-9)
        return sent

    @property
    def span_s(self) -> float:
        s = self._samples
        return s[-1][0] - s[0][0] if len(s) >= 2 else 0.0

    @property
    def known(self) -> bool:
        return self.span_s >= MIN_SPAN_S

    def rate(self) -> float:
        """Device ticks per host second (the nominal clock until enough samples)."""
        rate = self._measured
        return float(self.nominal_hz) if rate is None else rate
