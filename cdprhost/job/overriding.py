"""The speed and flow overrides: what the operator asks (M220 / M221, from any thread), and
the streamer's part, what it sends instead of the plan.

The streamer feeds the device from a planned batch a second or so at a time; before each
feed it asks :meth:`Overriding.apply` for the rest of the batch as it is to be sent now. While
both overrides are 100 % and the speeds join up, that is the plan itself; otherwise the rest
of the batch is replanned from the last segment sent (:mod:`cdprhost.motion.override`).
What the device already holds (at most the link's high watermark of motion, about 1 s at
1x) runs as it was sent: an override takes effect within that time plus one feed.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprhost.job.state import Overrides
from cdprhost.motion.limits import Caps
from cdprhost.motion.override import FlowEpoch, check_percent, retime, scale_flow
from cdprhost.motion.segments import DEFAULT_LIMITS, PlannedSegments, SegmentLimits


class OverrideRequests:
    """The operator's speed (M220) and flow (M221) overrides as factors: set from any thread,
    read by the streamer at each feed."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._speed = 1.0
        self._flow = 1.0

    def set(self, what: str, percent: float) -> float:
        """``what`` (speed | flow) at ``percent``; the factor set (ValueError outside the
        range :func:`~cdprhost.motion.override.check_percent` allows)."""
        factor = check_percent(what, percent)
        with self._lock:
            if what == "speed":
                self._speed = factor
            elif what == "flow":
                self._flow = factor
            else:
                raise ValueError(f"unknown override {what!r}")
        return factor

    def factors(self) -> tuple[float, float]:
        """(speed, flow) now."""
        with self._lock:
            return self._speed, self._flow


def requested_text(what: str, factor: float) -> str:
    """What the operator is told when an override is asked while printing."""
    return (
        f"{what} {factor * 100:g} % requested (what the device holds already, about a second of "
        "motion, runs as sent)"
    )


def resumed_text(ran: tuple[float, float], now: tuple[float, float]) -> str | None:
    """What a resumed print says when the interrupted one ran with an override (``ran``: its
    speed and flow in %; ``now``: the factors it resumes at): it starts again at what is set
    now, not at what it ran with. None when it ran at 100 %."""
    if ran == (100, 100):
        return None
    speed, flow = now
    return (
        f"the interrupted print ran at speed {ran[0]:g} %, flow {ran[1]:g} %; it resumes at "
        f"speed {speed * 100:g} %, flow {flow * 100:g} % (M220 / M221 set them again)"
    )


@dataclass
class LastFed:
    """The last program segment sent: its steps as planned and as sent, where, how fast."""

    planned_e: int
    steps: np.ndarray
    point: np.ndarray
    v_end: float
    number: int  # device segment number


class Overriding:
    """Applies the overrides to the segments the streamer is about to send."""

    def __init__(
        self,
        profile: Any,
        outlets: np.ndarray,
        clock_hz: float,
        limits: SegmentLimits = DEFAULT_LIMITS,
    ):
        self.e_steps_per_mm = float(profile.extruder.steps_per_mm)
        self.caps = Caps.for_profile(profile)
        self.outlets = outlets
        self.clock_hz = float(clock_hz)
        self.limits = limits
        self.speed = 1.0
        self.flow = 1.0
        self.epoch = FlowEpoch()
        self.last: LastFed | None = None
        self.time_ratio = 1.0
        self.stale = False  # the last apply could not retime (nothing sent yet): next feed
        self._told: Overrides | None = None

    def event(self) -> Overrides | None:
        """What is in effect, when it is news: other factors, or a time ratio 2 % off the
        one last told."""
        now = Overrides(round(self.speed * 100, 3), round(self.flow * 100, 3), self.time_ratio)
        told = self._told
        same = told is not None and (told.speed_pct, told.flow_pct) == (
            now.speed_pct,
            now.flow_pct,
        )
        if (
            same
            and told is not None
            and abs(now.time_ratio - told.time_ratio) <= 0.02 * told.time_ratio
        ):
            return None
        self._told = now
        return now

    def plain(self, v_start: float, segments_sent: int) -> bool:
        """A batch starting at ``v_start`` (as planned) goes out as planned: both overrides
        at 100 % and the speeds join up."""
        if self.speed != 1.0 or self.flow != 1.0 or not self.epoch.identity:
            return False
        last = self.last
        if last is None or last.number != segments_sent:
            return True
        return abs(last.v_end - v_start) < 1e-9

    def fed(self, planned_e: int, sent: PlannedSegments, k: int, number: int) -> None:
        """Segment ``k`` of ``sent`` went out as device segment ``number`` (``planned_e``:
        its extruder steps as planned)."""
        self.last = LastFed(
            planned_e,
            sent.steps_abs[k].copy(),
            sent.point[k].copy(),
            float(sent.v_end[k]),
            number,
        )

    def apply(
        self, planned: PlannedSegments, factors: tuple[float, float], segments_sent: int
    ) -> tuple[PlannedSegments, bool]:
        """The batch ``planned`` (the rest of a batch as planned) to send at ``factors``
        (speed, flow); True when the factors changed since the last call."""
        speed, flow = factors
        changed = (speed, flow) != (self.speed, self.flow)
        last = self.last
        if flow != self.flow:
            if last is not None:
                self.epoch = self.epoch.changed(flow, last.planned_e, int(last.steps[3]))
            else:
                self.epoch = FlowEpoch(0, 0, flow)
        self.speed, self.flow = speed, flow
        if not len(planned):
            return planned, changed
        prev = (
            last.steps
            if last is not None
            else (planned.steps_abs[0] - planned.delta[0]).astype(np.int64)
        )
        batch = scale_flow(planned, self.epoch, prev)
        self.stale = last is None and speed != 1.0
        if last is None:
            return batch, changed  # nothing sent yet: from the next feed on
        joined = last.number == segments_sent  # nothing else went out in between
        v0 = last.v_end if joined else float(batch.v_start[0])
        if speed == 1.0 and flow <= 1.0 and abs(v0 - float(batch.v_start[0])) < 1e-9:
            if changed:
                self.time_ratio = 1.0
            return batch, changed
        out = retime(
            batch,
            speed,
            start_point=last.point,
            v0=v0,
            caps=self.caps,
            outlets=self.outlets,
            clock_hz=self.clock_hz,
            limits=self.limits,
            flow=flow,
            e_steps_per_mm=self.e_steps_per_mm,
        )
        if changed or out.planned_s > 1.0:  # (a short rest says little of what follows)
            self.time_ratio = round(out.ratio, 4)
        return out.batch, changed
