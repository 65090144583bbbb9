"""The pty device's output to a host that does not read: what the pty cannot take is
dropped like a UART's, but counted and said, never lost without a trace."""

from __future__ import annotations

import os
import sys

import pytest

from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.pty_server import PtyServer

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")


def _drain(fd: int) -> bytes:
    out = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return out
        if not chunk:
            return out
        out += chunk


def test_output_a_host_leaves_unread_is_counted_and_said():
    notes: list[str] = []
    server = PtyServer(SimDevice(on_notice=notes.append))
    try:
        chunk = bytes(range(256)) * 64  # 16 KiB a write
        taken = [server.write(chunk) for _ in range(64)]  # 1 MiB: more than a pty holds
        assert server.dropped_tx_bytes > 0
        assert sum(taken) + server.dropped_tx_bytes == 64 * len(chunk)  # each byte one or other
        assert notes == ["the host does not read the port: device output is dropped"]

        os.set_blocking(server.slave, False)
        received = _drain(server.slave)  # the host reads at last
        assert received == b"".join(chunk[:n] for n in taken)  # what was taken, intact

        assert server.write(b"after") == 5
        assert notes[1] == (
            f"the host reads the port again: {server.dropped_tx_bytes} bytes of device output "
            f"were dropped meanwhile ({server.dropped_tx_bytes} in all)"
        )
        assert _drain(server.slave) == b"after"
    finally:
        server.close()
    assert notes[-1] == f"{server.dropped_tx_bytes} bytes of device output dropped in all"


def test_a_host_that_reads_everything_loses_nothing_and_hears_nothing():
    notes: list[str] = []
    server = PtyServer(SimDevice(on_notice=notes.append))
    try:
        os.set_blocking(server.slave, False)
        for k in range(20):
            assert server.write(bytes([k]) * 1000) == 1000
            assert _drain(server.slave) == bytes([k]) * 1000
    finally:
        server.close()
    assert server.dropped_tx_bytes == 0 and notes == []
