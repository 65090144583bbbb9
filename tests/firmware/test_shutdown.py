"""The AVR firmware's one shutdown path, in simavr (issue 20, deliverable 1).

- host silence after a non-thermal fault (UNDERRUN) with a heater on: the heater pin goes
  low within the watchdog time plus 0.1 s (the harness times the pin against the host's
  last byte);
- a thermal fault latches: CLEAR_FAULT is refused (EVENT CLEAR_REFUSED naming the code),
  and a thermal fault arriving while already faulted is reported too;
- every fault is reported, a second one included;
- a hung main loop: the heater lease, counted down by the step interrupt, switches the
  heaters' timer outputs off before the watchdog's interrupt would.
"""

from __future__ import annotations

import json
import os
import subprocess
import time

import pytest

from cdprhost.sim import avr_device
from firmware_protocol.messages import (
    ClearFault,
    Configure,
    ErrorCode,
    Event,
    EventCode,
    Flag,
    Flush,
    Segment,
    SetFan,
    SetHeater,
)
from tests.conformance.device import RawHost, start
from tests.firmware.raw import errors

pytestmark = [
    pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
    pytest.mark.timeout(300),
]

WATCHDOG_MS = 500


def _refused(h: RawHost) -> list[Event]:
    return [m for m in h.reports if isinstance(m, Event) and m.code == EventCode.CLEAR_REFUSED]


def _underrun(h: RawHost) -> None:
    """A segment that ends moving, then FLUSH: it starts and the queue runs dry."""
    h.send(Segment(ticks=2000, deltas=(40, 0, 0, 0), ramp=-1), Flush())
    h.wait_for(lambda: errors(h, ErrorCode.UNDERRUN), what="UNDERRUN")


def test_host_silence_after_an_underrun_turns_the_heater_off(avr_built, tmp_path):
    dev = start("avr", tmp_path, "--speedup", "1")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.send(Configure(watchdog_ms=WATCHDOG_MS, start_ticks=100_000, flow_ticks=12_500))
        h.send(SetHeater(0, 1000))
        h.wait_for(lambda: h.status().hotend_target_dc == 1000, what="target set")
        _underrun(h)
        st = h.status()
        assert st.flags & Flag.FAULT and st.hotend_target_dc == 1000  # kept for a resume
        h.keepalive = 0  # the host dies
        h.reports.clear()
        end = time.monotonic() + 3 * WATCHDOG_MS / 1000
        while time.monotonic() < end:
            h.pump(0.05)  # reads only: nothing is sent
        assert errors(h, ErrorCode.WATCHDOG), h.reports  # reported though faulted
    finally:
        h.close()
        dev.stop()
    silence = dev.stats()["heater_on_silence_max_s"]
    assert 0 < silence <= WATCHDOG_MS / 1000 + 0.1, silence


def test_thermal_fault_latches_and_a_second_fault_is_reported(avr_built, tmp_path):
    # the hotend's thermistor opens at device time 8 s, after the underrun: a reading
    # below MINTEMP with a target set is THERMAL_RUNAWAY (the element failing instead
    # would take the 40 s watch period: tests/conformance/test_heaters.py times that)
    dev = start("avr", tmp_path, "--speedup", "4", "--faults", "thermistor_open_after=8")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.send(SetHeater(0, 2000))
        _underrun(h)  # a first, non-thermal fault: the heater stays on
        h.wait_for(lambda: errors(h, ErrorCode.THERMAL_RUNAWAY), timeout=30, what="THERMAL_RUNAWAY")
        st = h.status()
        assert st.last_error == ErrorCode.THERMAL_RUNAWAY and st.hotend_target_dc == 0
        h.reports.clear()
        h.send(ClearFault())
        h.wait_for(lambda: _refused(h), what="CLEAR_FAULT refused")
        assert not any(
            isinstance(m, Event) and m.code == EventCode.FAULT_CLEARED for m in h.reports
        )
        assert h.status().flags & Flag.FAULT
        # a non-thermal fault after it is reported and does not replace the latch
        h.send(SetFan(3, 0))  # BAD_VALUE (one fan)
        h.wait_for(lambda: errors(h, ErrorCode.BAD_VALUE), what="BAD_VALUE")
        h.reports.clear()
        h.send(ClearFault())
        assert h.wait_for(lambda: _refused(h), what="refused again")[0].values == (
            ErrorCode.THERMAL_RUNAWAY,
        )
    finally:
        h.close()
        dev.stop()


HANG_AT_S = 4.0  # simulated seconds: after the heater is on at full power


def test_a_hung_main_loop_loses_the_heater_lease_before_the_watchdog_fires(avr_built, tmp_path):
    """The heaters run on timer outputs that go on by themselves: when the main loop
    hangs (the harness sends it into an endless loop, interrupts still running, and
    simavr's watchdog follows in its time), the step interrupt's lease switches them off
    0.3 s after the control loop last renewed it (every 100 ms), well before the
    watchdog's interrupt at 1 s."""
    stats = tmp_path / "stats.json"
    cmd = avr_device.harness_command(stats=str(stats))
    proc = subprocess.Popen(
        [*cmd, "--hang-main-after", str(HANG_AT_S)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None
        h = RawHost(proc.stdout.readline().strip())
        try:
            h.hello()
            h.send(SetHeater(0, 2000))  # far below: full power
            h.wait_for(lambda: h.status().hotend_target_dc == 2000, what="target set")
            assert h.status().clock < (HANG_AT_S - 1.0) * 100_000  # heating before the hang
            end = time.monotonic() + HANG_AT_S + 3.0
            while time.monotonic() < end:
                h.pump(0.05)
        finally:
            h.close()
    finally:
        proc.terminate()
        proc.wait(30)
    off = json.loads(stats.read_text())["heaters_off_after_hang_s"]
    assert 0.1 < off <= 0.35, off
