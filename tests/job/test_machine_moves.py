"""Machine operations on the embedded device: a move the device did not finish is an error."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.link import LinkError
from cdprhost.machine.operations import Machine
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.messages import ErrorCode
from firmware_protocol.segments import SegmentBatch, peak_step_rates


@pytest.fixture
def machine():
    profile = load_profile("paper-prototype")
    link = open_embedded()
    m = Machine(link, profile, MachineModel.from_profile(profile))
    m.home()
    yield m
    link.close()


def test_a_move_ends_homed_and_moved(machine):
    before = machine.status()
    st = machine.move_to((0.0, 0.0, 60.0))
    assert not st.faulted and st.homed_mask == 0b111 and st.steps[:3] != before.steps[:3]


def test_a_move_the_device_abandons_is_an_error_not_an_arrival(machine):
    """The device faults half-way (an underrun, a watchdog, a cut cable's endstop): it is
    idle then too, so waiting for idle alone reported the move done, with the modules no
    longer homed (the TUI's jog then showed no position; the wizard would measure there)."""
    dev = machine.link.device
    complete = dev.machine._complete
    calls = {"n": 0}

    def fail_midway(t):
        out = complete(t)
        calls["n"] += 1
        if calls["n"] == 5 and not dev.machine.fault:
            dev.machine.fail(ErrorCode.UNDERRUN, dev.machine.items_done, 0, t)
        return out

    dev.machine._complete = fail_midway
    with pytest.raises(LinkError, match="stopped during the move.*UNDERRUN"):
        machine.move_to((30.0, 10.0, 60.0))


def _fast_move(profile_step_rate: int | None) -> SegmentBatch:
    """The wire of one fast move (150 mm/s asked) on a device announcing 8,000 steps/s."""
    profile = load_profile("paper-prototype")
    config = SimConfig(max_step_rate=8_000, profile_step_rate=profile_step_rate)
    link = open_embedded(config=config)
    try:
        m = Machine(link, profile, MachineModel.from_profile(profile), feed_mm_s=150.0)
        m.home()
        m.move_to((0.0, 0.0, 60.0))
        sent: list[SegmentBatch] = []
        queue = link.queue_segments

        def spy(wire: SegmentBatch, **kw: Any) -> Any:
            sent.append(wire)
            return queue(wire, **kw)

        link.queue_segments = spy  # type: ignore[method-assign]
        st = m.move_to((40.0, -30.0, 20.0))
        assert not st.faulted and st.last_error == 0
        assert len(sent) == 1
        return sent[0]
    finally:
        link.close()


def test_a_direct_move_keeps_to_the_board_it_drives():
    """A jog or a calibration pose plans like a print, for the connected board: its speeds
    under the announced step rate (planned at the profile's own limits, a fast move on a
    board announcing 8,000 steps/s was refused, BAD_VALUE) and, on a board whose own
    stepping of a profile is slower (STEPPING), its fast ramps cut in pieces whose schedule
    blocks fit a frame."""
    whole = _fast_move(None)
    assert peak_step_rates(whole, 100_000).max() <= 8_000
    cut = _fast_move(4_000)
    assert peak_step_rates(cut, 100_000).max() <= 8_000
    assert len(cut) > len(whole)  # the ramps from and to rest, in pieces
    np.testing.assert_array_equal(cut.deltas.sum(axis=0), whole.deltas.sum(axis=0))
    assert cut.ticks.sum() == whole.ticks.sum()
