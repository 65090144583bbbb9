"""Resets of the AVR firmware booted as a Mega 2560 boots: through its stock stk500v2
bootloader (Debian's arduino-core-avr hex at the boot section, the Mega's fuses).

The harness resets the chip on request: SIGUSR1 pulls the RESET pin (what opening the
port does through the DTR auto-reset), SIGUSR2 hangs the main loop and lets the
watchdog's interrupt and reset follow. Its stats say, per enable pin, whether it went
high (driver off) between the last reset and the host's first byte after it.
"""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest

from cdprhost.sim import avr_device
from firmware_protocol.codes import BootCause
from firmware_protocol.messages import Boot, Enable
from tests.conformance.device import RawHost

pytestmark = [
    pytest.mark.skipif(
        not avr_device.BOOTLOADER_HEX.exists(),
        reason="the stk500v2 bootloader is missing: apt-get install -y arduino-core-avr",
    ),
    pytest.mark.timeout(120),
]

HELD = 0b0111  # the three modules; the extruder stays off


class Chip:
    def __init__(self, tmp: Path):
        self.stats_path = tmp / "stats.json"
        cmd = avr_device.harness_command(
            stats=str(self.stats_path), bootloader=avr_device.BOOTLOADER_HEX
        )
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.path = self.proc.stdout.readline().strip()
        self.host = RawHost(self.path)

    def boot(self) -> Boot:
        """The next BOOT, the host silent until it comes (bytes during the bootloader's
        wait would keep it waiting for a programmer)."""
        h = self.host
        h._open = False  # no keep-alives
        h.urgent.clear()
        return h.wait_for(
            lambda: next((m for m in h.urgent if isinstance(m, Boot)), None), 20, "BOOT"
        )

    def reset(self, sig: int) -> Boot:
        self.host._open = False
        self.host.pump(0.05)
        self.host.urgent.clear()
        self.proc.send_signal(sig)
        return self.boot()

    def stop(self) -> dict:
        self.host.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(30)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        return json.loads(self.stats_path.read_text())


@pytest.fixture
def chip(avr_built, tmp_path):
    c = Chip(tmp_path)
    yield c
    if c.proc.poll() is None:
        c.stop()


def _hold(chip: Chip) -> None:
    chip.host.hello()
    chip.host.send(Enable(HELD))
    chip.host.wait_for(lambda: chip.host.status().enabled_mask == HELD, 10, "motors enabled")


def test_a_power_on_boots_with_the_drivers_off_and_says_power_on(chip):
    boot = chip.boot()
    assert boot.cause == BootCause.POWER_ON and not boot.prev_valid
    chip.host.hello()
    assert chip.host.status().enabled_mask == 0
    stats = chip.stop()
    assert stats["enable_high_mask"] == 0b1111  # every EN pin high: drivers off


def test_a_watchdog_reset_through_the_bootloader_keeps_the_motors_held(chip):
    chip.boot()
    _hold(chip)
    boot = chip.reset(signal.SIGUSR2)
    assert boot.cause == BootCause.WATCHDOG, boot
    assert boot.prev_valid and boot.prev_items_done == 1  # the ENABLE
    chip.host.hello()
    assert chip.host.status().enabled_mask == HELD
    stats = chip.stop()
    assert stats["resets"] == 1
    # from the reset to the host's first byte the held drivers' EN pins never went high
    assert stats["enable_released_mask"] & HELD == 0, stats
    assert stats["enable_high_mask"] == 0b1000  # the extruder's driver stays off


def test_a_reset_at_connect_keeps_the_motors_held_and_the_counters(chip):
    """The DTR auto-reset of opening the port: the RESET pin, RAM kept."""
    chip.boot()
    _hold(chip)
    boot = chip.reset(signal.SIGUSR1)
    assert boot.cause == BootCause.EXTERNAL_RESET, boot
    assert boot.prev_valid and boot.prev_items_done == 1
    chip.host.hello()
    assert chip.host.status().enabled_mask == HELD
    stats = chip.stop()
    assert stats["resets"] == 1
    assert stats["enable_released_mask"] & HELD == 0, stats
