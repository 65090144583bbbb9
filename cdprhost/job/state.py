"""The print job state machine: states, events, and one pure reducer.

Everything that happens to a job arrives as an *event*; ``reduce(snapshot, event)``
returns the next immutable :class:`JobSnapshot`. The CLI progress bar and the TUI
both render snapshots, so there is one source of truth and no races between
worker threads and the screen (the shells apply events in their own thread).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

#: a temperature older than this (s) is shown as stale
STALE_S = 3.0


class JobState(StrEnum):
    IDLE = "idle"
    PREFLIGHT = "preflight"
    REFUSED = "refused"
    HEATING = "heating"
    PRINTING = "printing"
    PAUSING = "pausing"
    PAUSED = "paused"
    CANCELLING = "cancelling"
    CANCELLED = "cancelled"
    FAILED = "failed"
    DONE = "done"

    @property
    def finished(self) -> bool:
        return self in (JobState.REFUSED, JobState.CANCELLED, JobState.FAILED, JobState.DONE)

    @property
    def active(self) -> bool:
        return self in (
            JobState.HEATING,
            JobState.PRINTING,
            JobState.PAUSING,
            JobState.PAUSED,
            JobState.CANCELLING,
        )


_S = JobState
ALLOWED: dict[JobState, frozenset[JobState]] = {
    _S.IDLE: frozenset({_S.PREFLIGHT}),
    _S.PREFLIGHT: frozenset({_S.REFUSED, _S.HEATING, _S.PRINTING, _S.FAILED, _S.CANCELLED}),
    _S.HEATING: frozenset({_S.PRINTING, _S.PAUSING, _S.CANCELLING, _S.FAILED}),
    _S.PRINTING: frozenset({_S.HEATING, _S.PAUSING, _S.CANCELLING, _S.FAILED, _S.DONE}),
    _S.PAUSING: frozenset({_S.PAUSED, _S.CANCELLING, _S.FAILED}),
    _S.PAUSED: frozenset({_S.PRINTING, _S.HEATING, _S.CANCELLING, _S.FAILED}),
    _S.CANCELLING: frozenset({_S.CANCELLED, _S.FAILED}),
    _S.REFUSED: frozenset(),
    _S.CANCELLED: frozenset(),
    _S.FAILED: frozenset(),
    _S.DONE: frozenset(),
}

# ------------------------------------------------------------------ events


@dataclass(frozen=True)
class StateChanged:
    state: JobState
    reason: str = ""
    #: host monotonic clock when it happened (the elapsed time stops at the end)
    at: float = field(default_factory=time.monotonic, compare=False)


@dataclass(frozen=True)
class Planned:
    """Preflight/planning summary: totals the progress display needs."""

    layers: int
    moves: int
    estimated_time_s: float
    filament_mm: float
    segments: int = 0
    #: a resumed job: planned time of the file before its restart (progress counts from there)
    done_s: float = 0.0


@dataclass(frozen=True)
class Progress:
    """Executed motion reported by the device, mapped back to the program."""

    segments_done: int
    line: int
    layer: int
    device_time_s: float
    position: tuple[float, float, float] | None = None  # machine frame, mm
    sliders: tuple[float, float, float] | None = None
    tensions: tuple[float, float, float] | None = None
    steps: tuple[int, int, int, int] | None = None


@dataclass(frozen=True)
class Temperatures:
    hotend: float
    bed: float
    hotend_target: float
    bed_target: float
    age_s: float = 0.0  # how old the reading was when sent (a machine-level poll sets it)

    @property
    def stale(self) -> bool:
        """Too old to show as the present (mark it)."""
        return self.age_s > STALE_S


def temperatures_of(status: Any, age_s: float = 0.0) -> Temperatures:
    """The event from a device status (``cdprhost.link.DeviceStatus``; ``age_s``: how old it
    is, e.g. ``cdprhost.machine.poll.Reading.age_s``)."""
    return Temperatures(
        status.hotend_c, status.bed_c, status.hotend_target_c, status.bed_target_c, age_s
    )


@dataclass(frozen=True)
class LinkHealth:
    retransmits: int
    bad_frames: int
    naks: int = 0


@dataclass(frozen=True)
class Failure:
    reason: str
    last_line: int | None
    last_layer: int | None
    position: tuple[float, float, float] | None = None
    resume_file: str | None = None


@dataclass(frozen=True)
class Notice:
    text: str


@dataclass(frozen=True)
class Overrides:
    """The operator's speed and flow overrides (M220 / M221, percent) now applied to what is
    sent; ``time_ratio``: the motion still planned takes this times its planned time (about
    1 / speed, less where the limits cap it)."""

    speed_pct: float = 100.0
    flow_pct: float = 100.0
    time_ratio: float = 1.0


Event = StateChanged | Planned | Progress | Temperatures | LinkHealth | Failure | Notice | Overrides


class IllegalTransition(RuntimeError):
    pass


# ---------------------------------------------------------------- snapshot


@dataclass(frozen=True)
class JobSnapshot:
    state: JobState = JobState.IDLE
    reason: str = ""
    layers: int = 0
    moves: int = 0
    segments_total: int = 0
    estimated_time_s: float = 0.0
    filament_mm: float = 0.0
    done_s: float = 0.0  # a resumed job: the file's planned time before the restart
    segments_done: int = 0
    line: int = 0
    layer: int = 0
    device_time_s: float = 0.0
    position: tuple[float, float, float] | None = None
    sliders: tuple[float, float, float] | None = None
    tensions: tuple[float, float, float] | None = None
    steps: tuple[int, int, int, int] | None = None
    temperatures: Temperatures | None = None
    temperature_history: tuple[tuple[float, float, float], ...] = ()  # (device time, hotend, bed)
    link: LinkHealth = field(default_factory=lambda: LinkHealth(0, 0))
    failure: Failure | None = None
    notices: tuple[str, ...] = ()
    started_at: float | None = None  # host monotonic clock: first HEATING or PRINTING
    ended_at: float | None = None  # ... and the end (DONE, CANCELLED, FAILED, REFUSED)
    overrides: Overrides = field(default_factory=Overrides)
    #: machine seconds run (planned time scaled by the overrides in effect as it ran)
    machine_time_s: float = 0.0

    def elapsed_s(self, now: float) -> float:
        """Seconds since the job started printing (``now``: time.monotonic()); stops at its end."""
        if self.started_at is None:
            return 0.0
        end = self.ended_at if self.ended_at is not None else now
        return max(0.0, end - self.started_at)

    @property
    def fraction(self) -> float:
        if self.state is JobState.DONE:
            return 1.0
        if self.segments_total:
            return min(self.segments_done / self.segments_total, 1.0)
        if self.estimated_time_s:  # device time runs at the planned rate (from the restart on)
            total = self.done_s + self.estimated_time_s
            return min((self.done_s + self.device_time_s) / total, 1.0)
        return 0.0

    @property
    def eta_s(self) -> float | None:
        """Remaining device time: the planned time left, at the speed override in effect."""
        if not self.estimated_time_s:
            return None
        left = max(self.estimated_time_s - self.device_time_s, 0.0)
        return left * self.overrides.time_ratio


HISTORY = 600


def reduce(snap: JobSnapshot, event: Event) -> JobSnapshot:
    """The next snapshot. Raises IllegalTransition for a state change the machine forbids."""
    if isinstance(event, StateChanged):
        if event.state is snap.state:
            return snap
        if event.state not in ALLOWED[snap.state]:
            raise IllegalTransition(f"{snap.state.value} -> {event.state.value} is not allowed")
        started = snap.started_at
        if started is None and event.state in (JobState.HEATING, JobState.PRINTING):
            started = event.at
        ended = event.at if event.state.finished and snap.ended_at is None else snap.ended_at
        return replace(
            snap, state=event.state, reason=event.reason, started_at=started, ended_at=ended
        )
    if isinstance(event, Planned):
        return replace(
            snap,
            layers=event.layers,
            moves=event.moves,
            estimated_time_s=event.estimated_time_s,
            filament_mm=event.filament_mm,
            segments_total=event.segments,
            done_s=event.done_s,
        )
    if isinstance(event, Progress):
        ran = max(event.device_time_s - snap.device_time_s, 0.0) * snap.overrides.time_ratio
        return replace(
            snap,
            machine_time_s=snap.machine_time_s + ran,
            segments_done=event.segments_done,
            line=event.line,
            layer=event.layer,
            device_time_s=event.device_time_s,
            position=event.position or snap.position,
            sliders=event.sliders or snap.sliders,
            tensions=event.tensions or snap.tensions,
            steps=event.steps or snap.steps,
        )
    if isinstance(event, Temperatures):
        hist = (
            *snap.temperature_history[-(HISTORY - 1) :],
            (snap.device_time_s, event.hotend, event.bed),
        )
        return replace(snap, temperatures=event, temperature_history=hist)
    if isinstance(event, LinkHealth):
        return replace(snap, link=event)
    if isinstance(event, Failure):
        return replace(snap, failure=event)
    if isinstance(event, Notice):
        return replace(snap, notices=(*snap.notices[-49:], event.text))
    if isinstance(event, Overrides):
        return replace(snap, overrides=event)
    raise TypeError(f"unknown event {event!r}")
