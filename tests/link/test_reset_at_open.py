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
