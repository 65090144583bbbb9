"""The opening of a session: HELLO until IDENT, the protocol version, the device clock
measured (and CAPS asked for), CONFIGURE (watchdog, start threshold, flow reports) and,
with a 2.1 device, the machine's travel limits and heater gains (PROTOCOL.md 3.1).

A part of the link: it works on the link's :class:`~cdprhost.link.core.LinkCore` and
nothing else.
"""

from __future__ import annotations

import logging
import os

from cdprhost.link.core import LinkCore
from cdprhost.link.device_setup import DeviceSetup
from cdprhost.link.errors import ProtocolMismatch
from cdprhost.link.events import Identity
from cdprhost.link.tracker import boot_cause_text, decode_one
from cdprhost.link.tuning import (
    CLOCK_SYNC_S,
    HANDSHAKE_S,
    HELLO_BACKOFF,
    HELLO_FIRST_S,
    SLICE_S,
    START_PAYLOAD,
    STATUS_TIMEOUTS,
)
from firmware_protocol.codes import BootCause
from firmware_protocol.framing import Kind
from firmware_protocol.messages import (
    MINOR_SAFETY,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Boot,
    Configure,
    GetCaps,
    GetStatus,
    Hello,
    Ident,
    Message,
)

log = logging.getLogger("cdprhost.link.host_link")

# Before its first HELLO the host listens a little longer than a device without a session
# takes between its BOOT announcements (0.25 s): a device that has reset announces its
# cause and the counters it kept (what an exact resume after a reset needs), and a device
# in a session stays silent and gets its HELLO after the wait.
BOOT_LISTEN_S = 0.3
# When the open itself reset the board (DTR raised on a Mega's auto-reset, see
# serial_port), up to this long for its BOOT: a byte that reaches the stk500v2 bootloader
# during its wait (about 1 s after a reset) holds it in its programming loop until about
# 5 s after the last byte (measured in simavr with Debian's stk500boot_v2_mega2560.hex),
# so a HELLO sent then delays the firmware, and HELLOs resent with backoff would hold it
# for good. The BOOT ends the wait early; the silence timeout starts after it.
BOOTLOADER_WAIT_S = 3.0


class SessionSetup:
    """Handshake and configuration of one link (its core)."""

    def __init__(self, core: LinkCore):
        self.core = core
        self.configured_rate = 0.0
        self.start_ticks = 0
        self.setup = DeviceSetup()
        self.boot: Boot | None = None  # the device's BOOT heard before this session, if any
        # the longest a handshake may take while the line answers something (a noisy line
        # damages HELLO and IDENT alike); a line silent for the link timeout ends it sooner
        self.limit_s = max(core.timeout_s, HANDSHAKE_S)

    def handshake(self) -> Identity:
        """Listen first (``BOOT_LISTEN_S``, ``BOOTLOADER_WAIT_S`` after a reset at open) for the
        BOOT of a device that has reset (kept in ``boot``), then
        HELLO with a fresh nonce until the device answers IDENT, resent ever less often
        (HELLO_FIRST_S growing by HELLO_BACKOFF up to an eighth of the link timeout) for as
        long as the line answers (a byte within the link timeout; bytes that never held a
        frame's header for that long are a wrong baud rate) and at most ``limit_s``; check
        the protocol version;
        measure the device clock; configure the watchdog, start threshold and flow reports;
        send the machine set-up to a 2.1 device."""
        c = self.core
        with c.locked():
            nonce = int.from_bytes(os.urandom(2), "little") or 1
            c.new_session()
            reset = bool(getattr(c.t, "reset_at_open", False))
            listen = BOOTLOADER_WAIT_S if reset else BOOT_LISTEN_S
            start = c.t.now() + listen  # the first HELLO: sooner when the device speaks first
            dfr = c.ep.deframer
            hello = c.urgent_frame(Hello(nonce, PROTOCOL_MAJOR, PROTOCOL_MINOR))
            heard = start  # when the line last carried a byte (or the first HELLO)
            resend_at = start
            interval = HELLO_FIRST_S
            boots: list[Boot] = []
            rx_bytes = 0
            identity = None
            while identity is None:
                now = c.t.now()
                if now - heard > c.timeout_s or (
                    now - start > c.timeout_s and not dfr.frames + dfr.bad_frames
                ):  # silent, or bytes that never held a frame's header (a wrong baud rate)
                    raise c.silent_error(rx_bytes, "during the handshake")
                if now - start > self.limit_s:
                    raise c.silent_error(
                        rx_bytes,
                        f"during the handshake (the line answered, but no IDENT came through "
                        f"within {self.limit_s:g} s)",
                    )
                if now >= resend_at:
                    c.write([hello])
                    start = min(start, now)
                    resend_at = now + interval
                    interval = min(interval * HELLO_BACKOFF, max(HELLO_FIRST_S, c.timeout_s / 8))
                data = c.read(min(SLICE_S * 5, max(0.0, resend_at - now)))
                rx_bytes += len(data)
                if data.replace(hello, b"") and c.t.now() >= start:
                    heard = c.t.now()  # (a loopback's echo of HELLO is no answer)
                frames = dfr.feed(data)
                for k, fr in enumerate(frames):
                    if fr.kind != Kind.URGENT:
                        continue
                    msg = decode_one(fr.payload)
                    if isinstance(msg, Ident) and msg.nonce == nonce:
                        self._accept_ident(msg)
                        now = c.t.now()
                        for inc in c.ep.process(frames[k + 1 :], now):
                            c.dev.handle(inc, now)
                        identity = c.dev.identity
                        break
                    if isinstance(msg, Boot):
                        if msg.major != PROTOCOL_MAJOR:
                            self._mismatch(msg.major, msg.minor)
                        boots.append(msg)
                        if c.t.now() < start and (
                            not reset or msg.cause == BootCause.EXTERNAL_RESET
                        ):
                            # still listening: a device that announces its boot gets HELLO
                            # now. After a reset at open only the reset's own BOOT counts:
                            # the tail of an announcement the reset cut, or one sent before
                            # the open, came while the bootloader may still wait, and a
                            # HELLO then holds it about 5 s more (DeviceSilent, CI15)
                            resend_at = c.t.now()
        assert identity is not None
        # the announcement of this boot (an older one's, from before a reset, is stale)
        self.boot = next((b for b in reversed(boots) if b.boot_id == identity.boot_id), None)
        if self.boot is not None and self.boot.cause:
            log.info("%s: the device has reset (%s)", c.name, boot_cause_text(self.boot.cause))
        log.info(
            "%s: session with %s %s (protocol %d.%d, queue %d, clock %d Hz)",
            c.name,
            identity.firmware_name,
            identity.firmware_version,
            *identity.protocol,
            identity.queue_capacity,
            identity.clock_hz,
        )
        self._sync_clock()
        self.configure()
        self.send_setup()
        return identity

    @property
    def minor(self) -> int:
        """The minor version both ends speak (0 before a session)."""
        identity = self.core.dev.identity
        return min(identity.protocol[1], PROTOCOL_MINOR) if identity is not None else 0

    def _mismatch(self, major: int, minor: int) -> None:
        raise ProtocolMismatch(
            f"{self.core.name}: device speaks protocol {major}.{minor}, host speaks "
            f"{PROTOCOL_MAJOR}.{PROTOCOL_MINOR}; update the firmware or the host so the major "
            "versions match",
            device_version=(major, minor),
            host_version=(PROTOCOL_MAJOR, PROTOCOL_MINOR),
        )

    def _accept_ident(self, msg: Ident) -> None:
        c = self.core
        if msg.major != PROTOCOL_MAJOR:
            self._mismatch(msg.major, msg.minor)
        if msg.cpu_hz % msg.clock_hz:
            raise ProtocolMismatch(
                f"{c.name}: the device's cpu_hz {msg.cpu_hz} is not a multiple of its "
                f"clock_hz {msg.clock_hz} (PROTOCOL.md 5.5)",
                device_version=(msg.major, msg.minor),
                host_version=(PROTOCOL_MAJOR, PROTOCOL_MINOR),
            )
        c.ctx.cycles_per_tick = msg.cpu_hz // msg.clock_hz  # the blocks' prediction
        c.max_payload = min(c.max_payload, msg.max_payload)
        c.payload_limit = min(c.max_payload, START_PAYLOAD)
        c.ep.sender.window_bytes = msg.rx_window
        now = c.t.now()
        c.dev.accept_ident(msg, now)
        c.items_sent = msg.items_received
        c.segments_sent = msg.segments_received
        c.last_rx = now

    def _ask(self, *msgs: Message) -> int:
        """Send immediate commands now; returns the status count before them."""
        c = self.core
        with c.locked():
            count = c.dev.status_count
            for msg in msgs:
                c.send_immediate(msg)
            c.write(c.ep.flush(c.t.now()))
        return count

    def _sync_clock(self) -> None:
        """Status requests until the device clock's rate is measured (a few tens of ms); the
        first goes with GET_CAPS to a 2.1 device (its CAPS arrives before that STATUS)."""
        c = self.core
        start = c.t.now()
        first = True
        while not c.dev.clock.known:
            if c.t.now() - start > self.limit_s:  # (a silent device ends it sooner: the pump)
                raise c.silent_error(0, "while reading the device clock")
            caps = (GetCaps(),) if first and self.minor >= MINOR_SAFETY else ()
            first = False
            count = self._ask(*caps, GetStatus())

            def answered(n: int = count) -> bool:
                return c.dev.status_count > n

            c.wait(answered, STATUS_TIMEOUTS * c.timeout_s, "a status report")
            if not c.dev.clock.known:
                end = c.t.now() + CLOCK_SYNC_S / 3

                def later(e: float = end) -> bool:
                    return c.t.now() >= e

                c.wait(later, None, "clock samples")

    def configure(self) -> None:
        """Send the watchdog, the start threshold (most of the high watermark) and the flow
        interval (half the watermarks' gap), in device ticks at the measured clock rate."""
        c = self.core
        rate = c.clock_rate()
        marks = c.watermarks
        cap = 0xFFFF_FFFF
        start = min(cap, c.flow.start_ticks(rate))
        flow = min(cap, max(1, round((marks.high_s - marks.low_s) * rate / 2)))
        self.configured_rate = rate
        self.start_ticks = start
        self._ask(Configure(c.watchdog_ms, start, flow))
        log.debug("%s: configured start %d ticks, flow %d ticks", c.name, start, flow)

    def send_setup(self) -> None:
        """The machine's travel limits and heater gains, to a 2.1 device (else nothing)."""
        if self.minor < MINOR_SAFETY:
            return
        msgs = self.setup.messages()
        if msgs:
            self._ask(*msgs)
            log.debug("%s: machine set-up sent (%d messages)", self.core.name, len(msgs))
