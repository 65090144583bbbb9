"""The link's pump ends its slice with the news it found: a report that had already arrived
when the slice began is handled and the caller gets it at once. Before, the pump handled
it and then waited for more bytes up to its deadline: a feed whose last send was refused
for room in the device's ring sat 10-13 ms on the report that gave the room, and the AVR
step engine's ring (a few tens of ms of fast ramps) ran dry in half the runs of
tests/firmware/test_step_timing.py's ramps at 1x."""

from __future__ import annotations

import firmware_protocol.messages as M
from cdprhost.link.host_link import HostLink
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.message_codec import encode_message
from tests.link.test_link_credit import ScriptedDevice, segments


def _linked() -> tuple[ScriptedDevice, HostLink]:
    dev = ScriptedDevice(capacity=10)
    link = HostLink(dev, timeout_s=5.0, baud=None)
    link.handshake()
    dev.scripted = True
    return dev, link


def test_a_report_waiting_when_the_slice_begins_ends_it_without_a_wait():
    dev, link = _linked()
    link.queue_segments(segments(4))  # a frame in flight: its retransmission is the deadline
    after = dev.expected + 1
    dev.inbox += encode_frame(Kind.ACK, 0, after, encode_message(M.Flow(0x11, 9, 1, 1)))
    t = dev.t
    link._core.pump(0.25)
    assert link._core.credit() == 9  # the report was handled
    assert dev.t == t  # and the slice did not wait on the virtual clock for more


def test_a_slice_with_nothing_waiting_still_waits_for_bytes():
    dev, link = _linked()
    link._core.pump(0.0)  # what the handshake left
    assert not dev.inbox
    t = dev.t
    link._core.pump(0.05)
    assert dev.t > t  # no busy loop: an empty port is waited on
