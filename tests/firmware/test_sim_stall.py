"""The simulated board on a busy print PC: its process stopped for longer than the host
watchdog while the host keeps speaking. A chip never stops; the bytes the host sent meanwhile
wait in the pty, so the device must not count the stall as host silence (it once did: the
link's clock was the PC's wall time, and the resumed firmware saw 2 s without a byte and
tripped its watchdog on a host that spoke all along). Real silence still trips it."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from firmware_protocol.messages import Configure, ErrorCode, SetHeater
from tests.conformance.device import Device, RawHost, start
from tests.firmware.raw import errors

pytestmark = [
    pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
    pytest.mark.timeout(300),
]

WATCHDOG_MS = 500


def _harness_pid(dev: Device) -> int:
    """The simavr harness: the sim-device wrapper's child."""
    children = Path(f"/proc/{dev.proc.pid}/task/{dev.proc.pid}/children").read_text().split()
    assert len(children) == 1, children
    return int(children[0])


def test_a_stalled_simulator_is_not_host_silence_but_silence_still_trips(avr_built, tmp_path):
    dev = start("avr", tmp_path, "--speedup", "1")
    # keep-alives at a quarter of the watchdog, as the host's link sends them: at the
    # watchdog's own period (RawHost's default) a busy test PC alone made a gap past it
    h = RawHost(dev.path, keepalive=WATCHDOG_MS / 1000 / 4)
    try:
        h.hello()
        h.send(Configure(watchdog_ms=WATCHDOG_MS, start_ticks=100_000, flow_ticks=12_500))
        h.send(SetHeater(0, 1000))  # something to protect: the watchdog reports its trip
        h.wait_for(lambda: h.status().hotend_target_dc == 1000, what="target set")
        harness = _harness_pid(dev)
        os.kill(harness, signal.SIGSTOP)
        try:
            end = time.monotonic() + 4 * WATCHDOG_MS / 1000
            while time.monotonic() < end:
                h.pump(0.05)  # keep-alives go on into the pty
        finally:
            os.kill(harness, signal.SIGCONT)
        h.pump(1.0)
        assert not errors(h, ErrorCode.WATCHDOG), h.reports
        h.keepalive = 0  # now the host really falls silent
        end = time.monotonic() + 4 * WATCHDOG_MS / 1000
        while time.monotonic() < end:
            h.pump(0.05)
        assert errors(h, ErrorCode.WATCHDOG), h.reports
    finally:
        h.close()
        dev.stop()
    assert dev.stats()["stalled_s"] >= 1.5
