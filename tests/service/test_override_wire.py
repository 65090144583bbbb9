"""The wire's override request (M220 / M221 of a service-hosted print) and event."""

from __future__ import annotations

import pytest

from cdprhost.job.state import Overrides
from cdprhost.service import wire


def test_an_override_request_is_read_with_its_percent():
    msg = wire.decode_request(b'{"op": "override", "id": 3, "what": "speed", "percent": 150}')
    assert isinstance(msg, wire.Override)
    assert (msg.id, msg.what, msg.percent) == (3, "speed", 150.0)


@pytest.mark.parametrize(
    ("line", "where"),
    [
        (b'{"op": "override", "what": "speed", "percent": 0}', "override.percent"),
        (b'{"op": "override", "what": "flow", "percent": 9999}', "override.percent"),
        (b'{"op": "override", "what": "tempo", "percent": 100}', "override.what"),
        (b'{"op": "override", "what": "speed"}', "override.percent"),
    ],
)
def test_an_override_out_of_range_or_of_nothing_known_is_refused_naming_the_field(line, where):
    with pytest.raises(wire.WireError, match=f"^{where}"):
        wire.decode_request(line)


def test_the_overrides_event_crosses_intact():
    event = Overrides(120.0, 95.0, 0.81)
    assert wire.event_from_json(wire.event_to_json(event)) == event
