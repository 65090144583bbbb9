"""What the server asks of the machine: one small interface, three implementations.

The HTTP layer (:mod:`cdprhost.server.app`) never touches a job or a link: it talks to a
:class:`Printer`. :class:`cdprhost.server.service_printer.ServicePrinter` has the printer
service run the jobs (``cdprhost serve``); :class:`cdprhost.server.headless.HeadlessPrinter`
runs them itself (in-process tests); the terminal UI provides its own (``cdprhost tui
--listen``), so that a print started from a slicer is the TUI's print, shown and stoppable
there. Every refusal is a
:class:`Refused` carrying the reason the client is told (409).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from cdprhost.errors import CdprError
from cdprhost.gcode.errors import GcodeError
from cdprhost.job.state import JobSnapshot, JobState, Temperatures
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.prepared import Setup, prepare
from cdprhost.preflight.run import preflight_prepared
from cdprhost.profile.models import MachineProfile


class Refused(Exception):
    """The machine cannot do this now (409); the message says why."""


@dataclass(frozen=True)
class PrinterStatus:
    connected: bool = True
    file: Path | None = None  # the job's file (the last job's, once it ended)
    started_by: str = ""
    job: JobSnapshot = field(default_factory=JobSnapshot)
    started_at: float | None = None  # wall clock (epoch s)
    ended_at: float | None = None

    @property
    def busy(self) -> bool:
        return self.job.state.active or self.job.state is JobState.PREFLIGHT


def busy_reason(status: PrinterStatus) -> str:
    name = status.file.name if status.file else "a file"
    who = f", started by {status.started_by}" if status.started_by else ""
    return f"the machine is busy: {status.job.state.value} {name}{who}; nothing started"


def refuse_if_busy(status: PrinterStatus, closing: bool) -> None:
    """Refuse a start while the server shuts down or a job runs (or is checked)."""
    if closing:
        raise Refused("the server is shutting down; nothing started")
    if status.busy:
        raise Refused(busy_reason(status))


def refuse_unless_preflight_passes(
    path: Path, profile: MachineProfile, model: MachineModel, setup: Setup
) -> None:
    """Refuse a file that does not parse, cannot be read or fails preflight (the first
    violation named)."""
    try:
        report = preflight_prepared(prepare(path, profile, model, setup))
    except GcodeError as exc:
        raise Refused(f"the file does not parse: {exc}; nothing started") from None
    except (CdprError, OSError) as exc:
        raise Refused(f"{exc}; nothing started") from None
    if not report.ok:
        v = report.violations[0]
        raise Refused(preflight_refusal(report.violations_total, v.line, v.rule, v.detail))


def refuse_if_faulted(fault: str | None, clearable: bool, clear_fault: bool) -> None:
    """A device stopped by a fault starts nothing unless the server clears faults
    (``clear_fault``) and this one may be cleared from the host: nobody at the machine has
    looked at it. The refusal names the fault and the way out."""
    if not fault or (clear_fault and clearable):
        return
    how = (
        "check the machine, then restart `cdprhost serve --clear-fault` (or clear it in "
        "`cdprhost tui`)"
        if clearable
        else "it cannot be cleared from the host"
    )
    raise Refused(f"{fault}: {how}; nothing started")


class Printer(Protocol):
    def status(self) -> PrinterStatus:
        """Non-blocking: the machine and its current (or last) job."""

    def check_start(self, path: Path) -> None:
        """Blocking (preflight): raise :class:`Refused` unless ``path`` could start now: the
        machine idle and connected, and the file passing preflight."""

    def start(self, path: Path, who: str) -> None:
        """Start ``path`` (checked by :meth:`check_start` just before); ``who`` started it.
        Raises :class:`Refused` when the machine became busy meanwhile."""

    def pause(self, action: str) -> None:
        """``pause`` | ``resume`` | ``toggle``; :class:`Refused` when there is nothing to do."""

    def cancel(self) -> None:
        """Cancel the running job (the one safe-stop path); :class:`Refused` when none runs."""

    def uploaded(self, path: Path) -> None:
        """A file was stored in the upload folder (the TUI lists it)."""

    def temperatures(self) -> Temperatures | None:
        """Blocking (at most a device's status round trip): the newest heater reading, from
        the running job or asked of the device; None when there is none (not connected)."""


def preflight_refusal(total: int, line: int | None, rule: str, detail: str) -> str:
    """The 409 reason of a file that fails preflight (the first violation named)."""
    return (
        f"preflight refused the file: {total} violation(s); first at line {line}: "
        f"{rule}: {detail}; nothing started"
    )
