"""Travel protection on the AVR firmware in simavr (issue 20, deliverable 2).

- soft limits (SET_LIMITS) are checked on receipt for a homed module: a segment whose end
  leaves them is refused with ENDSTOP_HIT naming the module and that end, and nothing of
  it moves;
- the limit switch the harness models at the end of travel (physical +16400 steps, the
  Python model's overtravel) stops motion that runs into it: ENDSTOP_HIT with the module
  and its physical step, the segment recorded as aborted;
- the homing switch is pressed only at its flag, so moving through the travel does not
  read it (homing still finds it).
"""

from __future__ import annotations

import json
import os

import pytest

from firmware_protocol.messages import (
    ErrorCode,
    Event,
    EventCode,
    Flush,
    Home,
    Segment,
    SetLimits,
)
from tests.conformance.device import RawHost, start
from tests.firmware.raw import errors

pytestmark = [
    pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
    pytest.mark.timeout(300),
]

TO_REST = 255


def _homed(h: RawHost) -> None:
    """Home module 1 (index 0) to logical 0 at its switch (2 s of device time)."""
    h.send(Home(1, (0, 0, 0)))
    h.wait_for(
        lambda: any(isinstance(m, Event) and m.code == EventCode.HOMED for m in h.reports),
        timeout=30,
        what="HOMED",
    )


def _record(dev) -> list[dict]:
    return [json.loads(x) for x in dev.record.read_text().splitlines() if x.strip()]


def test_soft_limit_refuses_a_segment_on_receipt(avr_built, tmp_path):
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.send(SetLimits(0, 0, 1000))
        _homed(h)
        h.send(Segment(ticks=20_000, deltas=(800, 0, 0, 0), ramp=TO_REST), Flush())
        h.wait_for(lambda: h.status().steps[0] == 800, timeout=30, what="the first move")
        h.send(Segment(ticks=20_000, deltas=(400, 0, 0, 0), ramp=TO_REST), Flush())
        hit = h.wait_for(lambda: errors(h, ErrorCode.ENDSTOP_HIT), what="ENDSTOP_HIT")[0]
        assert (hit.axis, hit.value) == (0, 1200)
        assert h.status().steps[0] == 800  # nothing of it moved
    finally:
        h.close()
        dev.stop()
    assert [r["seq"] for r in _record(dev)] == [1]


def test_limit_switch_at_the_end_of_travel_stops_motion(avr_built, tmp_path):
    dev = start("avr", tmp_path, "--speedup", "4")
    h = RawHost(dev.path)
    try:
        h.hello()
        _homed(h)
        # 20000 steps braking from 6667 steps/s: through the travel (the homing switch is
        # not read as pressed on the way) into the limit switch at physical 16400
        h.send(Segment(ticks=600_000, deltas=(20_000, 0, 0, 0), ramp=TO_REST), Flush())
        hit = h.wait_for(lambda: errors(h, ErrorCode.ENDSTOP_HIT), timeout=60, what="hit")[0]
        assert hit.axis == 0 and 16_401 <= hit.value <= 16_401 + 40, hit
        assert 16_401 <= h.status().steps[0] <= 16_401 + 40
    finally:
        h.close()
        dev.stop()
    rows = _record(dev)
    assert rows[-1]["error"] == "endstop_hit" and 16_401 <= rows[-1]["steps"][0] <= 16_441
