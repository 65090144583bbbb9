"""What a raw host saw from the AVR firmware (tests/conformance/device.RawHost)."""

from __future__ import annotations

from firmware_protocol.messages import Error
from tests.conformance.device import RawHost


def errors(h: RawHost, code: int) -> list[Error]:
    """The ERROR reports of ``code`` received so far."""
    return [m for m in h.reports if isinstance(m, Error) and m.code == code]
