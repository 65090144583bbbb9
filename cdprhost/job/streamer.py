"""Streaming a planned program to a connected device: the job's part that holds the link.

The device's buffered motion is kept between the link's time watermarks
(:meth:`HostLink.feed`); the loop wakes on the device's reports, never on a blind
timer. Between sends it services the job: progress and temperature events, pause and
cancel requests, the resume point (each layer and every few seconds), the health of
the job log. Pause and cancel act within the motion already sent: a controlled
deceleration along the plan, a retract, then park (:mod:`cdprhost.job.stopping`); the
rest of the plan waits in :attr:`Streamer.pending` for a resume. The end of the program
is a FLUSH, and the job completes only when the device reports the last segment executed.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprhost.gcode import items as g
from cdprhost.job.options import PrintResult
from cdprhost.job.overriding import OverrideRequests, Overriding
from cdprhost.job.resume import SAVED_WHILE_PRINTING, ResumePoint, ResumeWriter
from cdprhost.job.resume_items import INSERTED_LINE, PlanSpec
from cdprhost.job.segment_map import SegmentInfo, SegmentMap
from cdprhost.job.state import (
    Event,
    JobState,
    LinkHealth,
    Notice,
    Progress,
    StateChanged,
    temperatures_of,
)
from cdprhost.job.stopping import Stop, StopControl
from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import tensions
from cdprhost.link import DeviceErrorEvent, DeviceStatus, HostLink, LinkError, quiet_collection
from cdprhost.machine.commands import device_messages
from cdprhost.motion.direct import to_wire
from cdprhost.motion.prepared import Setup
from cdprhost.motion.segments import DEFAULT_LIMITS, PlannedSegments, SegmentLimits
from cdprhost.profile.models import MachineProfile
from firmware_protocol.messages import BED, HOTEND, Flag, SetHeater

log = logging.getLogger(__name__)

SERVICE_S = 0.25  # longest the loop goes without servicing the job
PROGRESS_EVERY_S = 0.1
STATUS_EVERY_S = 0.5
_END = object()


@dataclass
class Requests:
    """Pause / resume / cancel from other threads, and a safe stop from the job itself (the
    speed and flow overrides: :class:`~cdprhost.job.overriding.OverrideRequests`)."""

    _set: set[str] = field(default_factory=set)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    stop_reason: str = ""
    cancel_reason: str = ""  # who cancelled (quit, a signal); "" = the operator

    def add(self, what: str) -> None:
        with self._lock:
            self._set.add(what)

    def take(self, what: str) -> bool:
        with self._lock:
            if what in self._set:
                self._set.discard(what)
                return True
            return False

    def has(self, *what: str) -> bool:
        with self._lock:
            return bool(self._set.intersection(what))

    def stop_safely(self, reason: str) -> None:
        """Stop at the next rest point and end the job as failed with ``reason``."""
        with self._lock:
            if not self.stop_reason:
                self.stop_reason = reason
            self._set.add("stop")


@dataclass
class StreamContext:
    """What the streamer needs from its job (everything but the link)."""

    gcode_path: str
    sha256: str
    profile: MachineProfile
    model: MachineModel
    plan: PlanSpec
    emit: Callable[[Event], None]
    state: Callable[[], JobState]
    requests: Requests
    overrides: OverrideRequests
    log_problem: Callable[[], str | None]
    idle_timeout_s: float = 30.0
    setup: Setup = field(default_factory=Setup)  # placement options the program was built with
    placement: tuple[float, float] = (0.0, 0.0)  # the X/Y shift they gave (mm)
    plan_profile: MachineProfile | None = None  # the profile planned on (capped to the board)
    limits: SegmentLimits = DEFAULT_LIMITS  # the device's shortest segment and step rate


class Streamer:
    """A connected job: streams planned segments and commands through a handshaken link."""

    def __init__(self, link: HostLink, ctx: StreamContext, resume: ResumeWriter | None):
        self.link = link
        self.ctx = ctx
        self.resume = resume
        self.clock_hz = link.identity.clock_hz if link.identity else 100_000
        self.map = SegmentMap(self.clock_hz)
        self.first_segment = link.segments_sent + 1
        # device number of program segment 0 (after a pause the re-sent plan gets new numbers)
        self.index_base = self.first_segment
        self.pending: deque[Any] = deque()  # plan items not sent yet, in order
        self.source: Iterator[Any] = iter(())
        self.stops = StopControl(self)
        self.overriding = Overriding(
            ctx.plan_profile or ctx.profile, ctx.model.geometry.outlets, self.clock_hz, ctx.limits
        )
        self.boot_id = link.identity.boot_id if link.identity else 0
        self.status: DeviceStatus | None = None
        self.heat_item = 0
        # heater waits sent and not reached yet: (the SetHeater's item, the wait's, the
        # reason); HEATING is shown once the device has set that target (the stream runs
        # ahead: during a G28 before an M190 nothing heats yet)
        self.heat_waits: deque[tuple[int, int, str]] = deque()
        self.home_items = (0, 0)  # the queue items of the last G28 (enable, home)
        self._at_rest = True
        self._last_progress = -1e9
        self._last_status = -1e9
        self._status_seen = 0
        self._origin = np.asarray(ctx.profile.build_volume.bed_origin, dtype=float)

    # ------------------------------------------------------------------ the stream
    def run(self, planned: Iterable[Any]) -> None:
        self.source = iter(planned)
        with quiet_collection():  # (no full collection of the host's heap mid-stream)
            while True:
                out = self.pending.popleft() if self.pending else next(self.source, _END)
                if out is _END:
                    break
                if isinstance(out, PlannedSegments):
                    self._segments(out)
                else:
                    self._command(out)
        self.link.flush()
        self.drain()

    def _segments(self, planned: PlannedSegments) -> None:
        i, n = 0, len(planned)
        link = self.link
        batch, wire, at = planned, to_wire(planned), 0  # what is sent: segment k is batch[k - at]
        fresh = True
        while i < n:
            self.service()
            if self.ctx.requests.has("pause", "cancel", "stop"):
                if i < n:  # the rest of the plan waits (a pause resumes it), as planned
                    self.pending.appendleft(planned.take(slice(i, n)))
                self.stops.stop_here()
                return
            factors = self.ctx.overrides.factors()
            ov = self.overriding
            if (
                factors != (ov.speed, ov.flow)
                or ov.stale
                or (fresh and not ov.plain(float(planned.v_start[0]), link.segments_sent))
            ):
                batch, _ = ov.apply(planned.take(slice(i, n)), factors, link.segments_sent)
                wire, at = to_wire(batch), i
                news = ov.event()
                if news is not None:
                    self.ctx.emit(news)
            fresh = False
            before = link.segments_sent
            j = at + link.feed(wire, i - at, max_wait=SERVICE_S)
            if j > i:
                part = batch.take(slice(i - at, j - at))
                self.map.add(before + 1, part)
                self.stops.sent(batch, j - at - 1, before + j - i)
                self.overriding.fed(
                    int(planned.steps_abs[j - 1, 3]), batch, j - at - 1, before + j - i
                )
                self.stops.note(planned.take(slice(i, j)))
                self._at_rest = bool(batch.v_end[j - at - 1] <= 1e-9)
                i = j

    def _command(self, item: Any) -> None:
        if isinstance(item, g.FilamentChange):
            self._filament_change(item)
            return
        msgs = device_messages(
            item,
            model=self.ctx.model,
            home_mm=self.ctx.profile.drive.home_mm,
            clock_hz=self.clock_hz,
        )
        if isinstance(item, g.DisplayMessage):
            self.ctx.emit(Notice(f"line {item.line}: {item.text}"))
        if not msgs:
            return
        self._check_heater_limits(msgs)
        numbers = self.link.send(*msgs)
        if isinstance(item, g.HomeCommand):
            self.home_items = (min(numbers), max(numbers))
        if isinstance(item, g.SetTemperature) and item.wait and item.target_c > 0:
            self.heat_item = max(numbers)
            self.stops.wait_sent(item)
            why = f"line {item.line}: waiting for {item.heater} {item.target_c:g} C"
            self.heat_waits.append((min(numbers), self.heat_item, why))
            self._heating_now()
        else:
            self.stops.note(item)
        if self.ctx.requests.has("pause", "cancel", "stop") and self._at_rest:
            self.stops.stop_here()

    def _check_heater_limits(self, msgs: list[Any]) -> None:
        """The device's announced maxima bound heater targets (it would refuse them)."""
        identity = self.link.identity
        if identity is None:
            return
        limits = {HOTEND: identity.hotend_max_c, BED: identity.bed_max_c}
        for m in msgs:
            if isinstance(m, SetHeater) and m.target_dc / 10 > limits.get(m.heater, 0.0):
                raise LinkError(
                    f"heater {m.heater} target {m.target_dc / 10:g} C is over the device's "
                    f"maximum {limits.get(m.heater, 0.0):g} C"
                )

    def _heating_now(self) -> None:
        """HEATING once the device has executed the target of a heater wait still ahead."""
        done = self.link.progress.items_done
        waits = self.heat_waits
        while waits and waits[0][1] <= done:  # reached and passed
            waits.popleft()
        if waits and waits[0][0] <= done and self.ctx.state() is JobState.PRINTING:
            self.set_state(JobState.HEATING, waits[0][2])

    def set_state(self, state: JobState, reason: str = "") -> None:
        if state is not self.ctx.state():
            self.ctx.emit(StateChanged(state, reason))

    # ------------------------------------------------------------------ pause / cancel
    def _filament_change(self, item: g.FilamentChange) -> None:
        """M600: the reader's park moves brought the machine to the park point; wait there
        (paused, heaters kept) until the operator resumes or cancels."""
        self.set_state(JobState.PAUSING, f"line {item.line}: M600 filament change")
        self.link.flush()
        self.drain(final=False)
        self.ctx.emit(Notice(f"line {item.line}: M600: change the filament, then resume"))
        self.set_state(JobState.PAUSED, f"line {item.line}: M600: change the filament, then resume")
        self.wait_for_resume()
        self.set_state(JobState.PRINTING, f"line {item.line}: M600: resumed")

    def wait_for_resume(self) -> None:
        """Paused: until a resume (the caller sets the state on) or a cancel (:class:`Stop`)."""
        req = self.ctx.requests
        while True:
            self.service(force_status=False)
            if req.has("stop"):
                self.set_state(JobState.CANCELLING)
                raise Stop(req.stop_reason)
            if req.take("cancel"):
                self.set_state(JobState.CANCELLING)
                raise Stop()
            if req.take("resume"):
                return
            self.link.wait_report(SERVICE_S)  # keep-alives go out while it waits

    def drain(self, final: bool = True) -> None:
        """Until the device has executed everything sent and stopped; with ``final`` it must
        report the last segment sent as executed (a job is complete only then)."""
        link = self.link
        last, since = -1, time.monotonic()
        told = not final
        while not link.idle():
            link.wait_report(SERVICE_S)
            self.service()
            if not told and self.ctx.requests.has("pause", "cancel"):
                told = True  # said, not silently ignored
                self.ctx.emit(Notice("the rest of the print is on the device already: it ends"))
            done = link.progress.items_done
            if done != last:
                last, since = done, time.monotonic()
            elif (
                time.monotonic() - since > self.ctx.idle_timeout_s
                and self.ctx.state() is not JobState.HEATING
                and not link.progress.flags & Flag.WAITING  # a heater wait holds the queue
            ):
                raise LinkError(
                    f"the device made no progress for {self.ctx.idle_timeout_s:g} s "
                    f"(executed {done} of {link.items_sent} items)"
                )
        self.service(force_status=True)
        p = link.progress
        if final and (p.segments_done < link.segments_sent or p.fault):
            raise LinkError(
                f"the device stopped after segment {p.segments_done} of {link.segments_sent}"
            )

    # ------------------------------------------------------------------ observation
    def service(self, force_status: bool = False) -> None:
        link = self.link
        for ev in link.poll(0.0):
            if isinstance(ev, DeviceErrorEvent):
                raise LinkError(f"device error {ev.text}")
        if link.progress.fault:
            # faulted without an error report reaching us: a faulted device discards what
            # it is sent, so streaming on would never end
            p = link.progress
            raise LinkError(
                f"the device stopped after segment {p.segments_done} of {link.segments_sent}: "
                "it reports a fault (its error report did not arrive)"
            )
        now = time.monotonic()
        if force_status:
            self._on_status(link.request_status())
        elif link.status_count > self._status_seen:  # a reply to an earlier request
            self._status_seen = link.status_count
            st = link.status()
            if st is not None:
                self._on_status(st)
        if not force_status and now - self._last_status > STATUS_EVERY_S:
            self._last_status = now
            self._status_seen = link.ask_status()  # answered while streaming goes on
        self._heating_now()
        if self.ctx.state() is JobState.HEATING and link.progress.items_done >= self.heat_item:
            self.set_state(JobState.PRINTING)
        info = self.map.lookup(link.progress.segments_done)
        if force_status or now - self._last_progress > PROGRESS_EVERY_S:
            self._last_progress = now
            self._progress(info)
        writer = self.resume
        if (
            writer is not None
            and info is not None
            and info.line != INSERTED_LINE
            and writer.due(info.layer, info.number, now)
        ):
            writer.save(self.point(SAVED_WHILE_PRINTING, info), now, info.layer)
        problem = self.ctx.log_problem()
        if problem:
            self.ctx.requests.stop_safely(problem)

    def _on_status(self, st: DeviceStatus) -> None:
        self.status = st
        self.ctx.emit(temperatures_of(st))
        c = self.link.counters
        self.ctx.emit(
            LinkHealth(c.retransmits, c.bad_frames + st.device_bad_frames, c.naks_received)
        )

    def _progress(self, info: SegmentInfo | None) -> None:
        if info is None:
            return
        if self.stops.parked:  # lifted and parked: the effector is not on the program's path
            self.progress_at_device()
            return
        self._emit_progress(info, info.point, info.steps)

    def progress_at_device(self) -> None:
        """Progress with the position the device's own step counters give (its latest status):
        after a park the program's last segment is not where the effector is (the screen and
        M114 must not show the nozzle on the part)."""
        info = self.executed()
        st = self.link.status()
        if info is None or st is None or st.homed_mask & 0b111 != 0b111:
            return
        model = self.ctx.model
        here = model.fk(model.sliders_from_steps(np.asarray(st.steps[:3]))[None, :])[0]
        if not np.all(np.isfinite(here)):
            return
        point = (float(here[0]), float(here[1]), float(here[2]))
        steps = (int(st.steps[0]), int(st.steps[1]), int(st.steps[2]), int(st.steps[3]))
        self._emit_progress(info, point, steps)

    def _emit_progress(
        self,
        info: SegmentInfo,
        point: tuple[float, float, float],
        steps: tuple[int, int, int, int],
    ) -> None:
        model = self.ctx.model
        t = tensions(np.asarray(point)[None, :], model.geometry.outlets, model.statics)[0]
        sliders = model.sliders_from_steps(np.asarray(steps[:3]))
        self.ctx.emit(
            Progress(
                info.number,
                info.line,
                info.layer,
                info.t_end_s,
                point,
                (float(sliders[0]), float(sliders[1]), float(sliders[2])),
                (float(t[0]), float(t[1]), float(t[2])),
                steps,
            )
        )

    # ------------------------------------------------------------------ where it is
    def executed(self, last_segment: int | None = None) -> SegmentInfo | None:
        """The last executed segment of this job (the device's number, or ``last_segment``)."""
        number = self.link.progress.segments_done if last_segment is None else last_segment
        if number < self.first_segment:
            return None
        return self.map.lookup(number)

    def fill(self, result: PrintResult, last: int | None = None) -> None:
        """The result's counts and last executed program segment (``last``: the device's
        number when known otherwise, e.g. after a reset)."""
        link = self.link
        info = self.executed(last)
        result.segments = max(0, (last or link.progress.segments_done) - self.first_segment + 1)
        counters = link.counters
        result.retransmits = counters.retransmits
        result.host_late_s = counters.host_late_worst_s
        result.lead_s = counters.lead_low_max_s
        result.last_line = info.line if info else None
        result.last_layer = info.layer + 1 if info else None
        result.final_steps = list(info.steps) if info else None

    def print_time(self, last: int | None = None) -> float:
        """Machine time printed by this job up to its last executed segment (planned time:
        the device may be unreachable now)."""
        info = self.executed(last)
        start = self.map.start_s
        if info is None or start is None:
            return 0.0
        return round(max(0.0, info.t_end_s - start), 6)

    def point(self, reason: str, info: SegmentInfo | None) -> ResumePoint:
        """The resume point at ``info`` (the last executed segment)."""
        st = self.status
        gcode_point = None
        e_mm = None
        if info is not None:
            p = np.asarray(info.point) - self._origin
            gcode_point = (float(p[0]), float(p[1]), float(p[2]))
            e_mm = float(info.e_mm)
        layer = info.layer + 1 if info is not None else None
        return ResumePoint(
            gcode=self.ctx.gcode_path,
            sha256=self.ctx.sha256,
            reason=reason,
            last_line=info.line if info else None,
            last_layer=layer,
            position=info.point if info else None,
            steps=info.steps if info else None,
            hotend_target=st.hotend_target_c if st else 0.0,
            bed_target=st.bed_target_c if st else 0.0,
            suggested_layer=max(layer or 1, 1),
            point=gcode_point,
            e_mm=e_mm,
            device_segment=info.number if info else 0,
            boot_id=self.boot_id,
            first_segment=self.index_base,
            plan=self.ctx.plan.to_json(),
            setup=self.ctx.setup.to_json(),
            placement=self.ctx.placement,
            speed_pct=round(self.ctx.overrides.factors()[0] * 100, 3),
            flow_pct=round(self.ctx.overrides.factors()[1] * 100, 3),
        )
