# mypy: disable-error-code="misc"
# (mixin methods typed with the class that uses them as ``self``: mypy only allows
# supertypes there, but the bodies are then checked against HostLink in full)
"""The opening of a session: HELLO until IDENT, the protocol version, the device clock
measured, and CONFIGURE (watchdog, start threshold, flow reports).

A mixin of :class:`cdprhost.link.host_link.HostLink` (its methods take the link as
``self``); kept apart so the streaming code and the session set-up read on their own.
"""

from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING

from cdprhost.link.errors import DeviceSilent, ProtocolMismatch
from cdprhost.link.events import Identity
from cdprhost.link.tracker import decode_one
from cdprhost.link.tuning import (
    CLOCK_SYNC_S,
    SLICE_S,
    START_PAYLOAD,
    START_WINDOW,
    STATUS_TIMEOUTS,
)
from firmware_protocol.framing import Kind
from firmware_protocol.messages import (
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Boot,
    Configure,
    Hello,
    Ident,
)
from firmware_protocol.segments import SegmentContext

log = logging.getLogger("cdprhost.link.host_link")

if TYPE_CHECKING:
    from cdprhost.link.host_link import HostLink


class SessionSetup:
    """HostLink's handshake and configuration (PROTOCOL.md section 3)."""

    def handshake(self: HostLink) -> Identity:
        """HELLO with a fresh nonce until the device answers IDENT; check the protocol version;
        measure the device clock; configure the watchdog, start threshold and flow reports."""
        with self._locked():
            nonce = int.from_bytes(os.urandom(2), "little") or 1
            self._ep.reset_session()
            self._ep.sender.window = min(START_WINDOW, self._max_window)
            self._last_retx = self._acked_clean = 0
            self._ctx = SegmentContext()
            start = self._t.now()
            resend_at = start
            rx_bytes = 0
            identity = None
            while identity is None:
                now = self._t.now()
                if now - start > self.timeout_s:
                    raise self._silent_error(rx_bytes, "during the handshake")
                if now >= resend_at:
                    self._write([self._urgent_frame(Hello(nonce, PROTOCOL_MAJOR, PROTOCOL_MINOR))])
                    resend_at = now + max(0.05, self.timeout_s / 8)
                data = self._read(min(SLICE_S * 5, max(0.0, resend_at - now)))
                rx_bytes += len(data)
                frames = self._ep.deframer.feed(data)
                for k, fr in enumerate(frames):
                    if fr.kind != Kind.URGENT:
                        continue
                    msg = decode_one(fr.payload)
                    if isinstance(msg, Ident) and msg.nonce == nonce:
                        self._accept_ident(msg)
                        now = self._t.now()
                        for inc in self._ep.process(frames[k + 1 :], now):
                            self._dev.handle(inc, now)
                        identity = self._identity()
                        break
                    if isinstance(msg, Boot) and msg.major != PROTOCOL_MAJOR:
                        self._mismatch(msg.major, msg.minor)
        log.info(
            "%s: session with %s %s (protocol %d.%d, queue %d, clock %d Hz)",
            self._t.name,
            identity.firmware_name,
            identity.firmware_version,
            *identity.protocol,
            identity.queue_capacity,
            identity.clock_hz,
        )
        self._sync_clock()
        self.configure()
        return identity

    def _mismatch(self: HostLink, major: int, minor: int) -> None:
        raise ProtocolMismatch(
            f"{self._t.name}: device speaks protocol {major}.{minor}, host speaks {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}; "
            "update the firmware or the host so the major versions match",
            device_version=(major, minor),
            host_version=(PROTOCOL_MAJOR, PROTOCOL_MINOR),
        )

    def _accept_ident(self: HostLink, msg: Ident) -> None:
        if msg.major != PROTOCOL_MAJOR:
            self._mismatch(msg.major, msg.minor)
        self._max_payload = min(self._max_payload, msg.max_payload)
        self._payload_limit = min(self._max_payload, START_PAYLOAD)
        self._ep.sender.window_bytes = msg.rx_window
        now = self._t.now()
        self._dev.accept_ident(msg, now)
        self._items_sent = msg.items_received
        self._segments_sent = msg.segments_received
        self._last_rx = now

    def _sync_clock(self: HostLink) -> None:
        """Status requests until the device clock's rate is measured (a few tens of ms)."""
        start = self._t.now()
        while not self._dev.clock.known:
            if self._t.now() - start > self.timeout_s:
                raise self._silent_error(0, "while reading the device clock")
            count = self.ask_status()
            self._wait(
                lambda c=count: self._dev.status_count > c,
                STATUS_TIMEOUTS * self.timeout_s,
                "a status report",
            )
            if not self._dev.clock.known:
                self.poll(CLOCK_SYNC_S / 3)

    def configure(self: HostLink) -> None:
        """Send the watchdog, the start threshold (most of the high watermark) and the flow
        interval (half the watermarks' gap), in device ticks at the measured clock rate."""
        rate = self.clock_rate
        marks = self.watermarks
        cap = 0xFFFF_FFFF
        start = min(cap, self._flow.start_ticks(rate))
        flow = min(cap, max(1, round((marks.high_s - marks.low_s) * rate / 2)))
        self._configured_rate = rate
        self._start_ticks = start
        self.send(Configure(self.watchdog_ms, start, flow))
        log.debug("%s: configured start %d ticks, flow %d ticks", self._t.name, start, flow)

    def _silent_error(self: HostLink, rx_bytes: int, when: str) -> DeviceSilent:
        name = self._t.name
        p = self._dev.progress
        when = f" {when}" if when else ""
        if rx_bytes and self._ep.deframer.frames == 0:
            text = (
                f"{name}: {rx_bytes} bytes but no valid frame{when} within {self.timeout_s:g} s; "
                "wrong baud rate, or not a cdpr device (or one speaking protocol 1)?"
            )
        else:
            text = (
                f"{name}: no answer from the device{when} within {self.timeout_s:g} s "
                f"(last reported executed segment {p.segments_done}); is it powered and connected?"
            )
        return DeviceSilent(text, last_segment=p.segments_done, last_item=p.items_done)

    # ------------------------------------------------------------------ pumping
