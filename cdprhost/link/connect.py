"""A handshaken :class:`HostLink` on a real port (the embedded simulation: :mod:`cdprhost.sim.embedded`)."""

from __future__ import annotations

from typing import Any

from cdprhost.link.host_link import HostLink
from cdprhost.link.serial_port import open_serial


def open_link(port: str, baud: int = 250_000, timeout_s: float = 2.0, **kwargs: Any) -> HostLink:
    """Open ``port`` exclusively, say HELLO, check the protocol version, measure the device
    clock, configure the session; a keep-alive thread then holds the session while idle."""
    transport = open_serial(port, baud, write_timeout_s=timeout_s)
    link = HostLink(transport, timeout_s=timeout_s, baud=baud, **kwargs)
    try:
        link.handshake()
    except BaseException:
        transport.close()
        raise
    link.start_keepalive()
    return link
