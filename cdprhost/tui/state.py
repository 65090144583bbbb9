"""The UI's single state value and the pure functions that advance it.

The app holds one :class:`UiState` (a Textual reactive) and replaces it only in
the UI thread. The print job's part is a :class:`~cdprhost.job.state.JobSnapshot`
advanced by the job reducer; the rest (connection, open file, jog target,
calibration, diagnosis) are small immutable views replaced whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from cdprhost.job.state import IllegalTransition, JobSnapshot, JobState, LinkHealth, reduce
from cdprhost.tui.control.views import (
    CalibrationView,
    DeviceStatusView,
    DiagnosisView,
    JogCheck,
    PreflightView,
    Vec3,
)


@dataclass(frozen=True)
class ConnectionView:
    status: str = "disconnected"  # disconnected | connecting | connected | error
    port: str = ""
    baud: int = 250000
    identity: tuple[tuple[str, str], ...] = ()
    error: str = ""
    health: LinkHealth | None = None


@dataclass(frozen=True)
class FileView:
    path: str = ""
    checking: bool = False
    preflight: PreflightView | None = None
    error: str = ""


@dataclass(frozen=True)
class DiagnoseView:
    session_dir: str = ""
    running: bool = False
    result: DiagnosisView | None = None
    error: str = ""


@dataclass(frozen=True)
class UiState:
    job: JobSnapshot = field(default_factory=JobSnapshot)
    job_id: int = 0
    job_path: str = ""
    connection: ConnectionView = field(default_factory=ConnectionView)
    file: FileView = field(default_factory=FileView)
    device: DeviceStatusView | None = None
    device_temps: tuple[tuple[float, float], ...] = ()  # (hotend, bed) polled while no job runs
    jog: JogCheck | None = None
    busy: str = ""  # a device operation in flight (jog, home, heaters...)
    calibration: CalibrationView = field(default_factory=CalibrationView)
    diagnose: DiagnoseView = field(default_factory=DiagnoseView)

    @property
    def job_active(self) -> bool:
        return self.job.state.active or self.job.state is JobState.PREFLIGHT

    @property
    def connected(self) -> bool:
        return self.connection.status == "connected"


def fold_job_events(state: UiState, items: list[tuple[int, Any]]) -> tuple[UiState, list[str]]:
    """Apply queued (job id, event) pairs of the current job, in order.

    Events of an older job are dropped. A transition the job machine forbids is
    not applied; its text is returned so the shell can show it.
    """
    snap = state.job
    problems: list[str] = []
    for job_id, event in items:
        if job_id != state.job_id:
            continue
        try:
            snap = reduce(snap, event)
        except IllegalTransition as exc:
            problems.append(str(exc))
    if snap is state.job:
        return state, problems
    return replace(state, job=snap), problems


def live_position(
    state: UiState,
) -> tuple[Vec3 | None, Vec3 | None, tuple[float, float, float] | None]:
    """(effector position, sliders, tensions): from the job while it runs, else the device."""
    job = state.job
    if job.position is not None and (state.job_active or state.device is None):
        return job.position, job.sliders, job.tensions
    if state.device is not None:
        return state.device.position, state.device.sliders, None
    return job.position, job.sliders, job.tensions


def hms(seconds: float | None) -> str:
    """Seconds as H:MM:SS ("--:--:--" when unknown)."""
    if seconds is None:
        return "--:--:--"
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
