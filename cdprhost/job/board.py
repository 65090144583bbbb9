"""The board a job plans for: what a connected device announced, as a profile records it
(:class:`~cdprhost.profile.device_record.DeviceRecord`, the ``[device]`` table)."""

from __future__ import annotations

import logging
from datetime import UTC, datetime

from pydantic import ValidationError

from cdprhost.link.events import DeviceCaps, Identity
from cdprhost.profile.device_record import DeviceRecord

log = logging.getLogger(__name__)


def announced_record(ident: Identity | None, caps: DeviceCaps | None) -> DeviceRecord | None:
    """What the connected board announced (IDENT's step rate, CAPS's shortest segment),
    stamped with its firmware and the time; None when it announced nothing usable."""
    if ident is None:
        return None
    try:
        return DeviceRecord(
            max_step_rate=ident.max_step_rate,
            min_segment_s=None if caps is None else caps.min_segment_ticks / ident.clock_hz,
            total_step_rate=None if caps is None else caps.total_step_rate,
            firmware=f"{ident.firmware_name} {ident.firmware_version}".strip(),
            recorded=datetime.now(UTC).isoformat(timespec="seconds"),
        )
    except ValidationError as exc:
        log.warning("the board announced limits a profile cannot record: %s", exc)
        return None
