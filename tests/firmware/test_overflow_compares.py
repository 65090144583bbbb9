"""The simulator serves a compare armed before a 16-bit timer's overflow for counts 0-3
of the next period on time, as the chip does (simavr 1.6 dropped it for the period, and
again each period while the CPU ran in the same phase: the step engine's rare stepper a
period, 4.1 ms, behind; firmware/sim/overflow_compares.c)."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest

from cdprhost.sim import avr_device

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")

PROGRAM = Path(__file__).parent / "programs" / "overflow_compare.c"


def _line_from(elf: Path, timeout: float = 30.0) -> str:
    """The program's first line on UART0, run in the harness (empty if none came)."""
    cmd = [str(avr_device.HARNESS), str(elf), "--speedup", "1000", "--time-limit", "5"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        pty = proc.stdout.readline().strip() if proc.stdout else ""
        assert pty.startswith("/dev/"), f"the harness printed {pty!r}"
        fd = os.open(pty, os.O_RDWR | os.O_NOCTTY)
        try:
            tty.setraw(fd)
            data, end = b"", time.monotonic() + timeout
            while b"\n" not in data and time.monotonic() < end and proc.poll() is None:
                if select.select([fd], [], [], 0.2)[0]:
                    data += os.read(fd, 256)
        finally:
            os.close(fd)
    finally:
        proc.kill()
        proc.wait()
    return data.decode(errors="replace").split("\n")[0].strip()


def test_a_compare_just_after_the_overflow_comes_in_the_same_period(avr_built, tmp_path):
    elf = tmp_path / "overflow_compare.elf"
    subprocess.run(
        ["avr-gcc", "-mmcu=atmega2560", "-DF_CPU=16000000UL", "-Os", "-std=c99", "-Wall"]
        + ["-Werror", str(PROGRAM), "-o", str(elf)],
        check=True,
    )
    # each of 256 compares (OCR3A 0-3, the spin's phase a cycle apart from trial to
    # trial) within 5,000 cycles of its arming; before, the program hung at the first
    # compare dropped (its phase, hence the drop, the same each period)
    assert _line_from(elf) == "trials 256 late 0"
