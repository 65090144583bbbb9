"""What a connected board lets a move plan use: its announced step rate and shortest
segment cap the profile's speeds (:func:`~cdprhost.motion.device_limits.caps_for_device`),
and a board whose own stepping of a profile is slower than its schedules (protocol 3.1's
``STEPPING``) has its fast ramps cut until their schedule blocks fit a frame. A print and
a direct move (jog, calibration pose, park) plan with the same limits."""

from __future__ import annotations

from cdprhost.link.events import DeviceCaps as AnnouncedCaps
from cdprhost.link.events import Identity
from cdprhost.link.host_link import HostLink
from cdprhost.motion.block_cuts import BlockLimits
from cdprhost.motion.device_limits import DeviceCaps, caps_for_device
from cdprhost.profile.models import MachineProfile


def block_limits(ident: Identity | None, caps: AnnouncedCaps | None) -> BlockLimits | None:
    """How a board whose schedules step faster than its own stepping of a profile
    (STEPPING's rate under IDENT's, protocol 3.1: the AVR's step engine beside its 400 us
    tick) wants its ramps cut; None when it steps every axis alike, or before the
    handshake."""
    if ident is None or caps is None or caps.profile_step_rate is None:
        return None
    if caps.profile_step_rate >= ident.max_step_rate:
        return None
    return BlockLimits.for_device(
        ident.cpu_hz,
        ident.clock_hz,
        caps.schedule_tolerance_cycles,
        ident.max_payload,
        caps.profile_step_rate,
    )


def board_caps(link: HostLink, profile: MachineProfile) -> DeviceCaps:
    """``profile`` planned for the board behind ``link`` as it announced itself (unchanged,
    with the default segment limits, before a handshake)."""
    ident, announced = link.identity, link.caps
    rate = ident.max_step_rate if ident else None
    shortest = announced.min_segment_ticks / ident.clock_hz if ident and announced else None
    total = announced.total_step_rate if announced else None
    return caps_for_device(profile, rate, shortest, block_limits(ident, announced), total)
