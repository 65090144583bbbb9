"""Machine operations on the embedded device: a move the device did not finish is an error."""

from __future__ import annotations

import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.link import LinkError
from cdprhost.machine.operations import Machine
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.messages import ErrorCode


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
