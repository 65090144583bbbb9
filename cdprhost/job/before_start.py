"""What the operator should know before a print starts on a connected device.

A device may be stopped by a fault (a watchdog that tripped when the last host vanished,
an e-stop), and the file may have a saved resume point from that very stop. Clearing the
fault is the operator's decision, and the resume point is offered, not forgotten: a
screen calls :func:`before_start`, shows :attr:`BeforeStart.question` when there is one,
and starts the job with ``PrintOptions(clear_fault=True)`` (and ``resume=...``) only once
the operator said so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cdprhost.errors import CdprError
from cdprhost.job.resume import ResumePoint, find_resume_point
from cdprhost.link.host_link import HostLink
from cdprhost.machine.prepare import describe_fault, fault_clearable
from firmware_protocol.messages import THERMAL_ERRORS


@dataclass(frozen=True)
class BeforeStart:
    fault: str | None  # the device's fault explained (None: not faulted)
    clearable: bool  # the host may clear it (thermal faults: no)
    resume: ResumePoint | None  # a saved point for this very file (same content and path)

    @property
    def question(self) -> str:
        """What to ask before starting ("" when there is nothing to ask)."""
        parts = []
        if self.fault is not None:
            parts.append(
                f"{self.fault}. Clear it and start?"
                if self.clearable
                else f"{self.fault}: it cannot be cleared from here"
            )
        if self.resume is not None and self.resume.exact:
            parts.append(
                f"This file stopped at line {self.resume.last_line} (layer "
                f"{self.resume.last_layer}, {self.resume.reason}): resume there instead?"
            )
        return " ".join(parts)


def before_start(
    link: HostLink, gcode: str | Path, resume_dir: str | Path | None = None
) -> BeforeStart:
    """The device's fault and the file's resume point, read now (nothing is changed)."""
    try:
        point = find_resume_point(gcode, resume_dir)
    except (OSError, CdprError):  # unreadable or malformed: no point to offer
        point = None
    st = link.request_status()  # a device stopped by a fault answers too
    exc = link.fault
    if exc is not None and not st.faulted:  # faulted in this session (an e-stop), the
        code = int(exc.code or 0)  # report older than the fault: the link says which
        return BeforeStart(
            f"the device is stopped by a fault ({exc})", code not in THERMAL_ERRORS, point
        )
    return BeforeStart(describe_fault(st), fault_clearable(st), point)
