"""The AVR device's relay between the host's pty and the harness's keeps what a pty did not take."""

from __future__ import annotations

import contextlib
import os
import select
import tty

from cdprhost.sim.avr_device import Relay
from firmware_protocol.device.faults import FaultSpec


def _drain(fd: int, want: int, rounds: int, relay: Relay) -> bytes:
    got = bytearray()
    for _ in range(rounds):
        relay.step(wait=0.001)
        while select.select([fd], [], [], 0)[0]:
            try:
                chunk = os.read(fd, 65536)
            except BlockingIOError:
                break
            if not chunk:
                break
            got += chunk
        if len(got) >= want:
            break
    return bytes(got)


def _feed(fd: int, data: bytes, done: int) -> int:
    """Write the next part of ``data`` the pty takes; how many bytes it took."""
    if done >= len(data):
        return 0
    with contextlib.suppress(BlockingIOError):
        return os.write(fd, data[done : done + 4096])
    return 0


def test_a_host_that_reads_late_loses_nothing_the_device_sent() -> None:
    harness_master, harness_slave = os.openpty()
    tty.setraw(harness_master)
    os.set_blocking(harness_master, False)
    relay = Relay(os.ttyname(harness_slave), FaultSpec())
    host = os.open(relay.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(host)
    try:
        sent = bytes(range(256)) * 2048  # 512 KiB: far more than a pty holds
        written = 0
        for _ in range(400):  # the device talks while the host does not read
            written += _feed(harness_master, sent, written)
            relay.step(wait=0.001)
        assert sum(len(p) for p in relay.pending.values()) > 0  # the host's pty is full
        got = bytearray()
        while len(got) < len(sent):
            written += _feed(harness_master, sent, written)
            more = _drain(host, len(sent), 1, relay)
            if not more and written >= len(sent) and not any(relay.pending.values()):
                break
            got += more
        assert bytes(got) == sent
    finally:
        relay.close()
        for fd in (host, harness_master, harness_slave):
            os.close(fd)
