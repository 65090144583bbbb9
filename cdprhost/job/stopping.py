"""Pause and cancel within the motion already sent, and resume exactly (the streamer's part).

The device holds at most the link's high watermark of motion (about a second at 1x,
:mod:`cdprhost.link.flow`); it cannot be taken back. On a pause, cancel or safe-stop
request the streamer stops feeding the plan and sends instead a deceleration along the
planned path from the end of the last sent segment (:func:`cdprhost.motion.stop.decelerate`:
the profile's acceleration limit, no extrusion), then a retract at rest. The stop is
effective once the device reports it at rest. Then:

- pause: lift by ``gcode.park_lift_mm`` and move to ``gcode.park_xy_mm`` (heaters kept),
  wait; on resume travel back above the place where extrusion stopped (the end of the last
  sent program segment), lower onto its exact steps, unretract, and send the rest of the
  plan again from there, accelerating from rest until it meets the plan
  (:func:`cdprhost.motion.stop.accelerate`);
- cancel or safe stop: raise :class:`Stop`; the runner parks and switches the heaters off
  as the profile says.

A cancel while the device holds its queue for a heater (nothing moves) or homes (at a
crawl) flushes the queue at once: an e-stop keeping heaters and motors, then the fault is
cleared (after homing was cut short the modules are not homed: nothing parks).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from cdprhost.job.state import JobState, Notice
from cdprhost.machine.operations import Machine
from cdprhost.motion.direct import to_wire
from cdprhost.motion.segments import PlannedSegments
from cdprhost.motion.stop import (
    Retimed,
    accelerate,
    concat_segments,
    decelerate,
    extruder_move,
    path_accel,
)
from firmware_protocol.messages import EstopFlag, Flag

if TYPE_CHECKING:
    from cdprhost.job.segment_map import SegmentMap
    from cdprhost.kinematics.machine import MachineModel
    from cdprhost.link import HostLink
    from cdprhost.profile.models import MachineProfile


class StreamContextView(Protocol):
    """What the stops read of the job's context (``streamer.StreamContext``)."""

    @property
    def profile(self) -> MachineProfile: ...

    @property
    def model(self) -> MachineModel: ...

    @property
    def requests(self) -> Any: ...

    @property
    def emit(self) -> Callable[[Any], None]: ...


class Stream(Protocol):
    """What the stops need of the stream they serve (:class:`cdprhost.job.streamer.Streamer`,
    which holds its :class:`StopControl`: it imports this module, never the reverse)."""

    link: HostLink
    clock_hz: int
    index_base: int
    heat_item: int
    home_items: tuple[int, int]
    pending: deque[Any]
    source: Iterator[Any]
    map: SegmentMap

    @property
    def ctx(self) -> StreamContextView: ...

    def set_state(self, state: JobState, reason: str = "") -> None: ...

    def wait_for_resume(self) -> None: ...

    def drain(self, final: bool = True) -> None: ...

    def service(self, force_status: bool = False) -> None: ...

    def progress_at_device(self) -> None: ...


log = logging.getLogger(__name__)

_END = object()


class Stop(Exception):
    """Left the stream stopped at rest: cancelled, or stopped safely (``reason``)."""

    def __init__(self, reason: str = ""):
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class LastSent:
    """The end of the last program segment sent: where a stop starts and a resume returns."""

    steps: np.ndarray  # (4,) absolute steps
    point: np.ndarray  # (3,) machine frame
    v_end: float  # mm/s
    t_end: float  # program time (s)
    number: int  # device segment number
    line: int


@dataclass(frozen=True)
class StopRecord:
    """The last controlled stop, for tests and figures: device segment numbers and speeds."""

    what: str  # "pause" | "cancel" | "stop"
    v0: float  # mm/s when the deceleration began
    accel: float  # mm/s^2 it used
    first_segment: int  # device number of its first segment (decel or retract)
    last_segment: int  # device number of the retract's last segment: at rest after it
    line: int  # program line where extrusion stopped
    host_s: float  # link clock from noticing the request to rest


class StopControl:
    """The streamer's stops (composition: it holds the streamer it serves)."""

    def __init__(self, streamer: Stream):
        self.s = streamer
        self.last: LastSent | None = None
        self.parked = False
        self.retracted = 0  # extruder steps pulled back by the stop
        self.record: StopRecord | None = None
        # what was sent since a heater wait the device has not passed yet (a pause there
        # flushes it and sends it again on resume), and where the plan stood before the wait
        self.replay: list[Any] | None = None
        self.before_wait: LastSent | None = None
        self.parked_from: tuple[np.ndarray, np.ndarray] | None = None  # module steps, point

    # ------------------------------------------------------------ bookkeeping
    def sent(self, batch: PlannedSegments, k: int, number: int) -> None:
        """Segment ``k`` of ``batch`` went out as device segment ``number``."""
        self.last = LastSent(
            batch.steps_abs[k].copy(),
            batch.point[k].copy(),
            float(batch.v_end[k]),
            float(batch.t_end[k]),
            number,
            int(batch.line[k]),
        )

    def wait_sent(self, item: Any) -> None:
        """A heater wait (``item``) went out: record what follows until the device passes it."""
        self.replay = [item]
        self.before_wait = self.last

    def note(self, item: Any) -> None:
        """``item`` (a command, or the segments of one feed) went out."""
        if self.replay is None:
            return
        if self.s.link.progress.items_done >= self.s.heat_item:
            self.replay = None  # the wait is over: nothing to send again
        else:
            self.replay.append(item)

    def _gather(self, done: Callable[[PlannedSegments], Retimed]) -> Retimed:
        """The pending plan's segments (pulled from the source as needed) until ``done``
        says the retimed motion has met its goal, or the plan ends."""
        s = self.s
        parts: list[PlannedSegments] = []
        idx = 0
        result: Retimed | None = None
        while True:
            if idx >= len(s.pending):
                nxt = next(s.source, _END)
                if nxt is _END:
                    break
                s.pending.append(nxt)
            item = s.pending[idx]
            idx += 1
            if isinstance(item, PlannedSegments) and len(item):
                parts.append(item)
                result = done(concat_segments(parts))
                if result.merged:
                    return result
        if result is None:
            return done(concat_segments(parts)) if parts else Retimed(_no_segments(), 0)
        return result

    def _accel(self, path: PlannedSegments, start: np.ndarray) -> float:
        s = self.s
        return path_accel(s.ctx.profile, s.ctx.model.geometry.outlets, start, path.point)

    # ------------------------------------------------------------------ stop
    def stop_here(self) -> None:
        """Stop within the motion sent; pause (returns once resumed) or raise :class:`Stop`."""
        s = self.s
        req = s.ctx.requests
        link = s.link
        cancel = req.has("cancel", "stop")
        what = "stop" if req.has("stop") else "cancel" if cancel else "pause"
        s.set_state(
            JobState.CANCELLING if cancel else JobState.PAUSING,
            "stopping within the motion already sent",
        )
        t0 = link.now()
        if cancel and self._homing():
            self._flush_queue()  # the modules stop where they are, not homed
        elif self._at_heater_wait():
            self._flush_heater_wait()
            if not cancel:  # resumed later: the wait and what followed go out again
                self._send_again_after_resume()
                self._decelerate_and_retract(what)  # at rest: the retract only
        else:
            self._decelerate_and_retract(what)
        s.drain(final=False)
        if self.record is not None:
            self.record = _with_time(self.record, link.now() - t0)
        line = self.last.line if self.last is not None else 0
        s.ctx.emit(
            Notice(f"{what}: at rest {link.now() - t0:.2f} s after the request (line {line})")
        )
        if req.has("stop"):
            raise Stop(req.stop_reason)
        if cancel:
            req.take("cancel")
            raise Stop()
        req.take("pause")
        self._park()
        s.set_state(JobState.PAUSED, f"stopped at line {line}; lifted and parked; heaters kept")
        s.wait_for_resume()  # raises Stop on a cancel
        self._resume()

    def stop_after_bug(self, reason: str) -> bool:
        """A bug in the host (not the link): the same controlled stop as a cancel when the
        link still works; False when that fails too (the caller e-stops)."""
        self.s.ctx.requests.stop_safely(reason)
        try:
            self.stop_here()
        except Stop:
            return True
        except Exception:
            log.exception("the controlled stop after an internal error failed")
        return False

    def _decelerate_and_retract(self, what: str) -> None:
        s = self.s
        link = s.link
        last = self.last
        first = link.segments_sent + 1
        v0, accel = 0.0, 0.0
        steps = np.zeros(4, dtype=np.int64) if last is None else last.steps.copy()
        if last is not None and last.v_end > 1e-9:
            v0 = last.v_end
            seen: dict[str, float] = {}

            def stop_along(path: PlannedSegments) -> Retimed:
                seen["a"] = self._accel(path, last.point)
                return decelerate(
                    path, last.steps, last.point, v0, seen["a"], s.clock_hz, last.t_end
                )

            stopping = self._gather(stop_along)
            accel = seen.get("a", 0.0)
            if stopping.count:
                link.queue_segments(to_wire(stopping.segments))
                steps = stopping.segments.steps_abs[-1].copy()
        ext = s.ctx.profile.extruder
        # nothing of the plan sent yet: nothing to pull back
        pull = int(round(ext.retract_mm * ext.steps_per_mm)) if last is not None else 0
        retract = extruder_move(
            steps, -pull, ext.retract_speed_mm_s, ext.max_accel_mm_s2, ext.steps_per_mm, s.clock_hz
        )
        if len(retract):
            link.queue_segments(to_wire(retract))
        self.retracted = pull
        link.flush()
        line = last.line if last is not None else 0
        self.record = StopRecord(what, v0, accel, first, link.segments_sent, line, 0.0)

    def _at_heater_wait(self) -> bool:
        """A heater wait sent and not done: until the device holds at it (the motion before
        a wait ends at rest) or has passed it; True when it holds there."""
        s = self.s
        link = s.link
        while link.progress.items_done < s.heat_item:
            if link.progress.flags & Flag.WAITING:
                return True
            link.wait_report(0.25)
            s.service()
        return False

    def _homing(self) -> bool:
        """The device is homing (or about to: only the G28's own items are left before it):
        homing is slow, at a crawl; a cancel need not wait for it."""
        first, last = self.s.home_items
        return first - 1 <= self.s.link.progress.items_done < last

    def _flush_heater_wait(self) -> None:
        """The queue is held by a heater wait (nothing moves): flush it at once."""
        self._flush_queue()

    def _flush_queue(self) -> None:
        """Stop the device's queue at once (an e-stop keeping heaters and motors), then clear
        the e-stop's fault: only for what may stop dead (a heater wait, homing's crawl)."""
        link = self.s.link
        link.emergency_stop(flags=EstopFlag.KEEP_HEATERS | EstopFlag.KEEP_MOTORS)
        link.clear_fault()
        link.request_status()  # a fresh report: the fault flags of the e-stop are history
        link.poll(0.0)  # the e-stop's own error report: ours, not a failure
        self.record = None

    def _send_again_after_resume(self) -> None:
        s = self.s
        replay, self.replay = self.replay or [], None
        s.pending.extendleft(reversed(replay))
        s.map.drop_after(s.link.progress.segments_done)
        self.last = self.before_wait

    # ------------------------------------------------------------ park / resume
    def _machine(self) -> Machine:
        s = self.s
        gc = s.ctx.profile.gcode
        return Machine(s.link, s.ctx.profile, s.ctx.model, feed_mm_s=gc.travel_speed_mm_s)

    def _here(self, machine: Machine) -> np.ndarray | None:
        st = machine.status()
        if st.homed_mask & 0b111 != 0b111:
            return None
        model = self.s.ctx.model
        here = model.fk(model.sliders_from_steps(np.asarray(st.steps[:3]))[None, :])[0]
        return here if np.all(np.isfinite(here)) else None

    def _park(self) -> None:
        """Pause: lift clear of the part, then move to the profile's park point."""
        machine = self._machine()
        here = self._here(machine)
        if here is None:
            return
        profile = self.s.ctx.profile
        gc = profile.gcode
        top = profile.build_volume.z_max_mm
        z = float(min(here[2] + gc.park_lift_mm, top))
        route = [(float(here[0]), float(here[1]), z), (gc.park_xy_mm[0], gc.park_xy_mm[1], z)]
        self.parked_from = (np.asarray(machine.status().steps[:3], dtype=np.int64), here)
        machine.move_through(np.asarray(route, dtype=float))
        self.parked = True
        self.s.progress_at_device()  # the position shown is the parked one

    def _resume(self) -> None:
        """Back onto the exact steps where extrusion stopped, unretract, re-send the plan from
        there accelerating from rest."""
        s = self.s
        link = s.link
        last = self.last
        machine = self._machine()
        here = self._here(machine)
        # where the plan goes on: the last program segment sent, else where the park began
        back = (last.steps[:3], last.point) if last is not None else self.parked_from
        if back is not None and here is not None and self.parked:
            steps, point = back
            above = (float(point[0]), float(point[1]), float(max(here[2], point[2])))
            route = np.asarray([above, tuple(point)], dtype=float)
            machine.move_through(route, end_steps=steps)
        self.parked, self.parked_from = False, None
        ext = s.ctx.profile.extruder
        push = extruder_move(
            last.steps if last is not None else np.zeros(4, np.int64),
            self.retracted,
            ext.unretract_speed_mm_s,
            ext.max_accel_mm_s2,
            ext.steps_per_mm,
            s.clock_hz,
        )
        if len(push):
            link.queue_segments(to_wire(push))
            link.wait_idle()
        self.retracted = 0
        if last is not None:
            self._ramp_from_rest(last)
            # the re-sent plan continues the program's numbering from the next segment
            s.index_base = link.segments_sent + 1 - (last.number + 1 - s.index_base)
        s.set_state(JobState.PRINTING, f"resumed at line {last.line if last else 0}")

    def _ramp_from_rest(self, last: LastSent) -> None:
        """The pending plan retimed to start from rest where it stopped."""
        s = self.s

        def start_along(path: PlannedSegments) -> Retimed:
            a = self._accel(path, last.point)
            return accelerate(path, last.point, a, s.clock_hz, last.t_end)

        ramp = self._gather(start_along)
        if not ramp.merged:
            log.warning("the plan ends before the restart meets its speed")
        left, off = ramp.count, 0
        out: deque[Any] = deque()
        for item in s.pending:
            if left > 0 and isinstance(item, PlannedSegments):
                k = min(len(item), left)
                out.append(ramp.segments.take(slice(off, off + k)))
                if k < len(item):
                    out.append(item.take(slice(k, len(item))))
                off, left = off + k, left - k
            else:
                out.append(item)
        s.pending = out


def _with_time(rec: StopRecord, host_s: float) -> StopRecord:
    return StopRecord(
        rec.what, rec.v0, rec.accel, rec.first_segment, rec.last_segment, rec.line, host_s
    )


def _no_segments() -> PlannedSegments:
    return extruder_move(np.zeros(4, np.int64), 0, 1.0, 1.0, 1.0, 1.0)
