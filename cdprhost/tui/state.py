"""The UI's single state value and the pure functions that advance it.

The app holds one :class:`UiState` (a Textual reactive) and replaces it only in
the UI thread. The print job's part is a :class:`~cdprhost.job.state.JobSnapshot`
advanced by the job reducer; the rest (connection, open file, jog target,
calibration, diagnosis, console, history) are small immutable views replaced whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from cdprhost.job.state import (
    IllegalTransition,
    JobSnapshot,
    JobState,
    LinkHealth,
    Notice,
    Progress,
    StateChanged,
    Temperatures,
    reduce,
)
from cdprhost.tui.control.eta import Eta, estimate, heating_rate, machine_rate
from cdprhost.tui.control.views import (
    CalibrationView,
    ConsoleLine,
    DeviceStatusView,
    DiagnosisView,
    JobRecord,
    JogCheck,
    PreflightView,
    ResumeView,
    Vec3,
)

RATE_SAMPLES = 120
CONSOLE_LINES = 500
NOTICE_SHOWN_S = 15.0
"""A job's notice stays on its status line this long (the console keeps them all)."""
STALE_AFTER_S = 2.0
"""Temperatures older than this are marked stale (the job reports every 0.5 s, the idle
status comes every second: two missed readings)."""


@dataclass(frozen=True)
class ConnectionView:
    status: str = "disconnected"  # disconnected | connecting | connected | error
    port: str = ""
    baud: int = 250000
    identity: tuple[tuple[str, str], ...] = ()
    error: str = ""
    health: LinkHealth | None = None
    simulated: bool = False  # the embedded simulated device (no hardware)


@dataclass(frozen=True)
class FileView:
    path: str = ""
    checking: bool = False
    preflight: PreflightView | None = None
    error: str = ""
    resume: ResumeView | None = None


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
    job_started: float = 0.0  # wall clock (epoch s) when the job was started
    job_ended: float = 0.0  # wall clock when it reached a final state (0: not yet)
    notice_at: float | None = None  # monotonic time of the job's newest notice
    job_resumed_from: int | None = None  # 1-based layer a resumed job restarts at
    job_resume_line: int | None = None  # the line an exact resume continues at
    job_request: str = ""  # "pause" or "cancel" asked of the job and not yet taken up
    rate_samples: tuple[tuple[float, float], ...] = ()  # (monotonic s, machine s) printing
    temps_at: float | None = None  # monotonic time of the newest temperature reading
    temp_samples: tuple[tuple[float, float, float], ...] = ()  # (monotonic s, hotend, bed)
    heat_rates: tuple[tuple[str, float], ...] = ()  # measured warm-up °C per wall s, by heater
    connection: ConnectionView = field(default_factory=ConnectionView)
    file: FileView = field(default_factory=FileView)
    device: DeviceStatusView | None = None
    device_temps: tuple[tuple[float, float], ...] = ()  # (hotend, bed) polled while no job runs
    jog: JogCheck | None = None
    busy: str = ""  # a device operation in flight (jog, home, heaters...)
    calibration: CalibrationView = field(default_factory=CalibrationView)
    diagnose: DiagnoseView = field(default_factory=DiagnoseView)
    console: tuple[ConsoleLine, ...] = ()
    history: tuple[JobRecord, ...] = ()  # newest first
    recent: tuple[str, ...] = ()  # recently opened G-code files, newest first

    @property
    def job_active(self) -> bool:
        return self.job.state.active or self.job.state is JobState.PREFLIGHT

    @property
    def connected(self) -> bool:
        return self.connection.status == "connected"


def shown_job_state(state: UiState) -> JobState:
    """The job state as the operator should see it: a pause or cancel that was asked for and
    waits for the next rest point shows as PAUSING / CANCELLING at once."""
    s = state.job.state
    if state.job_request == "cancel" and s.active and s is not JobState.CANCELLING:
        return JobState.CANCELLING
    if state.job_request == "pause" and s in (JobState.PRINTING, JobState.HEATING):
        return JobState.PAUSING
    return s


def _request_after(request: str, old: JobState, new: JobState) -> str:
    """A pending request is taken up once the job reaches (or passes) the state it asked for."""
    if not request or new is old:
        return request
    if new.finished or new in (JobState.PAUSED, JobState.CANCELLING):
        return ""
    if request == "pause" and new is JobState.PAUSING:
        return ""
    return request


def rates_measured(
    rates: tuple[tuple[str, float], ...],
    samples: tuple[tuple[float, float, float], ...],
    reading: Temperatures,
) -> tuple[tuple[str, float], ...]:
    """The heaters' warm-up rates, updated from the samples of a heater still well below its
    target (near it, the controller slows the rise down)."""
    out = dict(rates)
    for k, name, target in ((1, "hotend", reading.hotend_target), (2, "bed", reading.bed_target)):
        now = reading.hotend if k == 1 else reading.bed
        if target <= 0 or now > target - 5.0:
            continue
        r = heating_rate([(t[0], t[k]) for t in samples])
        if r is not None:
            out[name] = r
    return tuple(sorted(out.items()))


def fold_job_events(
    state: UiState, items: list[tuple[int, Any]], now: float = 0.0, wall: float = 0.0
) -> tuple[UiState, list[str]]:
    """Apply queued (job id, event) pairs of the current job, in order; ``now`` is the
    monotonic time they are applied at (temperature age, the time estimate's rate, notice
    age), ``wall`` the wall clock (when the job ended).

    Events of an older job are dropped. A transition the job machine forbids is
    not applied; its text is returned so the shell can show it.
    """
    snap = state.job
    problems: list[str] = []
    request, samples, temps_at = state.job_request, state.rate_samples, state.temps_at
    heat, notice_at, ended = state.temp_samples, state.notice_at, state.job_ended
    rates = state.heat_rates
    for job_id, event in items:
        if job_id != state.job_id:
            continue
        before = snap.state
        try:
            snap = reduce(snap, event)
        except IllegalTransition as exc:
            problems.append(str(exc))
            continue
        if isinstance(event, StateChanged):
            request = _request_after(request, before, snap.state)
            if snap.state.finished and not ended:
                ended = wall
        elif isinstance(event, Notice):
            notice_at = now
        elif isinstance(event, Temperatures):
            temps_at = now
            heat = (*heat[-(RATE_SAMPLES - 1) :], (now, event.hotend, event.bed))
            if snap.state is JobState.HEATING:
                rates = rates_measured(rates, heat, event)
        elif isinstance(event, Progress) and snap.state is JobState.PRINTING:
            samples = (*samples[-(RATE_SAMPLES - 1) :], (now, snap.machine_time_s))
    if snap is state.job:
        return state, problems
    return (
        replace(
            state,
            job=snap,
            job_request=request,
            rate_samples=samples,
            temps_at=temps_at,
            temp_samples=heat,
            notice_at=notice_at,
            job_ended=ended,
            heat_rates=rates,
        ),
        problems,
    )


def for_open_file(state: UiState) -> UiState:
    """The state as the print screen shows it: a finished job of another file than the one
    open now is not shown (its figures, lines and times belong to that file)."""
    if state.job_active or not state.job_path or state.job_path == state.file.path:
        return state
    return replace(
        state,
        job=JobSnapshot(),
        job_started=0.0,
        job_ended=0.0,
        notice_at=None,
        rate_samples=(),
        job_request="",
    )


def resumed_share(state: UiState) -> float:
    """The share of the file's moves done before a resumed job started (0 when it was not
    resumed, or the file's toolpath is unknown): a resumed job's progress continues from there."""
    pre = state.file.preflight
    tp = pre.toolpath if pre is not None and state.job_path == state.file.path else None
    if tp is None or not len(tp.line) or state.job_resumed_from is None or state.job.done_s:
        return 0.0  # (a job that says what was done before its restart counts from there)
    if state.job_resume_line is not None:
        done = int(np.count_nonzero(tp.line < state.job_resume_line))
    else:
        done = int(np.count_nonzero(tp.layer < state.job_resumed_from - 1))
    return done / len(tp.line)


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


def job_eta(state: UiState, default_rate: float) -> Eta | None:
    """Time left of the running job (or of the open file, before it starts), heating
    included; None when there is nothing to estimate."""
    job = state.job
    temps: dict[str, float | None] = {"hotend": None, "bed": None}
    if job.temperatures is not None and state.job_active:
        temps = {"hotend": job.temperatures.hotend, "bed": job.temperatures.bed}
    elif state.device is not None:
        temps = {"hotend": state.device.hotend, "bed": state.device.bed}
    pre = state.file.preflight
    waits = pre.toolpath.heat_waits if pre is not None and pre.toolpath is not None else ()
    if state.job_path != state.file.path and state.job_active:
        waits = ()  # the open file is not the one printing
    rate = machine_rate(state.rate_samples, default_rate)
    heating = dict(state.heat_rates)
    tp = pre.toolpath if pre is not None else None
    first = int(tp.line[0]) if tp is not None and len(tp.line) else 0
    if state.job_active and job.state is not JobState.PREFLIGHT:
        left = job.eta_s if job.eta_s is not None else 0.0
        return estimate(
            left,
            line=job.line,
            temperatures=temps,
            heat_waits=waits,
            rate=rate,
            heating_now=heating,
            first_move_line=first,
        )
    if pre is not None and pre.ok and not state.job_active:
        return estimate(
            pre.estimated_time_s,
            line=0,
            temperatures=temps,
            heat_waits=waits,
            rate=rate,
            heating_now=heating,
            first_move_line=first,
        )
    return None


@dataclass(frozen=True)
class TemperaturesShown:
    current: tuple[float | None, float | None]
    targets: tuple[float, float]
    history: tuple[tuple[float, float], ...]
    stale_s: float | None  # the readings' age when too old to trust


def shown_temperatures(state: UiState, now: float) -> TemperaturesShown:
    """The temperatures to show: the running job's readings, else the device's latest status;
    either marked stale once older than ``STALE_AFTER_S``. A job that just ended shows its
    last reading until the device answers again, stale only once it is that old (never
    "STALE 0s")."""
    age = temperature_age(state, now)
    stale = round(age) if age is not None and age > STALE_AFTER_S else None
    job, dev = state.job, state.device
    if state.job_active and job.temperatures is not None:
        t = job.temperatures
        history = tuple((h, b) for _, h, b in job.temperature_history)
        return TemperaturesShown((t.hotend, t.bed), (t.hotend_target, t.bed_target), history, stale)
    if dev is not None:
        return TemperaturesShown(
            (dev.hotend, dev.bed), (dev.hotend_target, dev.bed_target), state.device_temps, stale
        )
    if job.temperatures is not None:  # a job just ended: its last reading, until the device
        t = job.temperatures  # answers again (marked as old as it is)
        return TemperaturesShown((t.hotend, t.bed), (t.hotend_target, t.bed_target), (), stale)
    return TemperaturesShown((None, None), (0.0, 0.0), (), None)


def shown_notice(state: UiState, now: float) -> str:
    """The job's newest notice while it is recent ("" after ``NOTICE_SHOWN_S``)."""
    notices = state.job.notices
    if not notices or state.notice_at is None or now - state.notice_at > NOTICE_SHOWN_S:
        return ""
    return notices[-1]


def elapsed(state: UiState, wall: float) -> float | None:
    """Wall-clock time of the job: up to now, or to its end once it has ended."""
    if not state.job_started:
        return None
    return max((state.job_ended or wall) - state.job_started, 0.0)


def temperature_age(state: UiState, now: float) -> float | None:
    """Seconds since the newest temperature reading (None: never had one)."""
    return None if state.temps_at is None else max(now - state.temps_at, 0.0)


def hms(seconds: float | None) -> str:
    """Seconds as H:MM:SS ("--:--:--" when unknown)."""
    if seconds is None:
        return "--:--:--"
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
