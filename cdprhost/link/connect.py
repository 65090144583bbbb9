"""Ways to get a handshaken :class:`HostLink`: a real port, or the embedded simulation."""

from __future__ import annotations

from cdprhost.link.host_link import HostLink
from cdprhost.link.serial_port import open_serial
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.faults import FaultSpec
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.harness import DEFAULT_BAUD, VirtualBench


def open_link(port: str, baud: int = 250_000, timeout_s: float = 2.0, **kwargs) -> HostLink:
    """Open ``port`` exclusively, say HELLO, check the protocol version."""
    transport = open_serial(port, baud, write_timeout_s=timeout_s)
    link = HostLink(transport, timeout_s=timeout_s, baud=baud, **kwargs)
    try:
        link.handshake()
    except BaseException:
        transport.close()
        raise
    return link


def open_embedded(
    *,
    config: SimConfig | None = None,
    faults: FaultSpec | str | None = None,
    speedup: float | None = None,
    observer=None,
    baud: int | None = DEFAULT_BAUD,
    timeout_s: float = 2.0,
    **kwargs,
) -> HostLink:
    """A HostLink to a simulated device in this process (no pty, no threads).

    Time is virtual and runs as fast as the CPU allows; with ``speedup`` X it is
    paced to at most X times real time. ``link.device`` is the SimDevice (its
    ``record`` lists the executed segments); ``baud`` None removes the wire-time model.
    """
    spec = FaultSpec.parse(faults) if isinstance(faults, str) else (faults or FaultSpec())
    device = SimDevice(config, spec, observer)
    bench = VirtualBench(device, faults=spec, baud=baud, pace=speedup)
    link = HostLink(bench, timeout_s=timeout_s, device=device, baud=baud, **kwargs)
    link.handshake()
    return link
