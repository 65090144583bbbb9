"""The simulated device inside this process, behind a :class:`~cdprhost.link.HostLink`.

No pty and no threads: the device model runs on a virtual clock that advances while the
link is pumped (as fast as the CPU allows, or paced to ``speedup`` x real time).
"""

from __future__ import annotations

from typing import Any

from cdprhost.link.host_link import HostLink
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.faults import FaultSpec
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.harness import DEFAULT_BAUD, VirtualBench


def open_embedded(
    *,
    config: SimConfig | None = None,
    faults: FaultSpec | str | None = None,
    speedup: float | None = None,
    observer: Any = None,
    baud: int | None = DEFAULT_BAUD,
    timeout_s: float = 2.0,
    record_keep: int | None = None,
    **kwargs: Any,
) -> HostLink:
    """A HostLink to a simulated device in this process (no pty, no threads).

    Time is virtual and runs as fast as the CPU allows; with ``speedup`` X it is
    paced to at most X times real time. ``link.device`` is the SimDevice (its
    ``record`` lists the executed segments; ``record_keep`` n holds only about the newest
    n of them); ``baud`` None removes the wire-time model.
    """
    spec = FaultSpec.parse(faults) if isinstance(faults, str) else (faults or FaultSpec())
    device = SimDevice(config, spec, observer, record_keep=record_keep)
    bench = VirtualBench(device, faults=spec, baud=baud, pace=speedup)
    link = HostLink(bench, timeout_s=timeout_s, device=device, baud=baud, **kwargs)
    link.handshake()
    return link
