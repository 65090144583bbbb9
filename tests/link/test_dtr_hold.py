"""Opening the port resets a Mega only once: HUPCL cleared, DTR stays up across closes."""

from __future__ import annotations

import os
import sys
import termios

import pytest

from cdprhost.link.serial_port import open_serial

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="Linux ttys")


def test_the_first_open_clears_hupcl_so_later_opens_make_no_dtr_edge():
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        attrs = termios.tcgetattr(slave)
        attrs[2] |= termios.HUPCL  # as the kernel leaves a freshly plugged board's tty
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        first = open_serial(path, 250000)
        first.close()
        assert not termios.tcgetattr(slave)[2] & termios.HUPCL  # DTR kept on close
        second = open_serial(path, 250000)
        second.close()
        assert not termios.tcgetattr(slave)[2] & termios.HUPCL
    finally:
        os.close(master)
        os.close(slave)
