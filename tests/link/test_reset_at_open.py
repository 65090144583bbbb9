"""The open that reset the board is known (HUPCL was set: DTR rose), so the handshake waits
for the bootloader and the firmware's BOOT before its HELLO; later opens reset nothing."""

from __future__ import annotations

import os
import sys
import termios

import pytest

from cdprhost.link import DeviceSilent, HostLink
from cdprhost.link.serial_port import open_serial
from cdprhost.link.session_setup import BOOT_LISTEN_S, BOOTLOADER_WAIT_S
from firmware_protocol.codes import BootCause
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.message_codec import encode_message
from firmware_protocol.messages import PROTOCOL_MAJOR, PROTOCOL_MINOR, Boot

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="Linux ttys")


def test_only_the_open_that_raised_dtr_says_it_reset_the_board(tmp_path):
    master, slave = os.openpty()
    port = tmp_path / "ttyACM0"  # not a /dev/pts path: a tty with a DTR line, as far as it knows
    port.symlink_to(os.ttyname(slave))
    try:
        attrs = termios.tcgetattr(slave)
        attrs[2] |= termios.HUPCL  # as the kernel leaves a freshly plugged board's tty
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        first = open_serial(str(port), 250000)
        first.close()
        second = open_serial(str(port), 250000)
        second.close()
        assert first.reset_at_open and not second.reset_at_open
    finally:
        os.close(master)
        os.close(slave)


class Silent:
    """A virtual line that never answers; records when the host first wrote."""

    name = "silent"

    def __init__(self, reset_at_open: bool) -> None:
        self.t = 0.0
        self.first_write: float | None = None
        self.reset_at_open = reset_at_open

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> None:
        if self.first_write is None:
            self.first_write = self.t

    def read(self, timeout: float) -> bytes:
        self.t += max(timeout, 0.001)
        return b""

    def close(self) -> None:
        pass


@pytest.mark.parametrize("reset", [False, True], ids=["no-reset", "reset-at-open"])
def test_the_first_hello_waits_for_a_boot_and_longer_after_a_reset(reset):
    line = Silent(reset)
    with pytest.raises(DeviceSilent, match="no answer"):
        HostLink(line, timeout_s=1.0).handshake()
    wait = BOOTLOADER_WAIT_S if reset else BOOT_LISTEN_S
    assert line.first_write is not None and wait <= line.first_write < wait + 0.1
    assert line.t >= line.first_write + 1.0  # the silence is counted from the first HELLO


class ResetAtOpen(Silent):
    """A Mega whose open reset it: before the reset's own BOOT (cause EXTERNAL_RESET, at
    ``boot_at``) the line carries the tail of an announcement the reset cut and a whole
    announcement sent before the open (cause POWER_ON); then nothing."""

    def __init__(self, boot_at: float) -> None:
        super().__init__(True)
        self.boot_at = boot_at
        self.sent = 0

    def read(self, timeout: float) -> bytes:
        before = self.t
        self.t += max(timeout, 0.001)
        if self.sent == 0:
            self.sent = 1
            stale = Boot(7, BootCause.POWER_ON, PROTOCOL_MAJOR, PROTOCOL_MINOR, 0, 0, 0)
            frame = encode_frame(Kind.URGENT, 0, 0, encode_message(stale))
            return frame[5:] + frame  # a cut announcement's tail, then an older one whole
        if self.sent == 1 and before < self.boot_at <= self.t:
            self.sent = 2
            fresh = Boot(8, BootCause.EXTERNAL_RESET, PROTOCOL_MAJOR, PROTOCOL_MINOR, 1, 0, 0)
            return encode_frame(Kind.URGENT, 0, 0, encode_message(fresh))
        return b""


def test_after_a_reset_at_open_only_the_resets_own_boot_ends_the_listening():
    # bytes or an older BOOT that came while the stk500v2 bootloader still waited made the
    # host say HELLO at once, and a byte reaching the bootloader then holds it about 5 s
    # more: the handshake ran out (DeviceSilent, 4 bytes and no frame, in CI)
    line = ResetAtOpen(boot_at=1.2)
    with pytest.raises(DeviceSilent):
        HostLink(line, timeout_s=1.0).handshake()
    assert line.first_write is not None and 1.2 <= line.first_write < 1.3
