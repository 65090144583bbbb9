"""The print job: preflight, then stream the planned program to the device.

Imperative shell around the pure pipeline (``cdprhost.motion.pipeline``) and the
link (``cdprhost.link``). ``run()`` blocks; pause/resume/cancel requests come from
other threads. Pause and cancel take effect at the next point where the planned
motion comes to rest (every extrusion path ends at rest before a retraction, so
this is at most a path away): the queue drains, nothing stops mid-segment.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.gcode import items as g
from cdprhost.gcode.errors import GcodeError
from cdprhost.job.log import JobLog
from cdprhost.job.prefetch import Prefetch
from cdprhost.job.resume import ResumePoint, resume_path_for
from cdprhost.job.resume_items import from_layer
from cdprhost.job.segment_map import SegmentMap, first_rest_index
from cdprhost.job.state import (
    Event,
    Failure,
    JobState,
    LinkHealth,
    Notice,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
)
from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import tensions
from cdprhost.link import DeviceErrorEvent, DeviceStatus, HostLink, LinkError
from cdprhost.machine.commands import device_messages, heaters_off
from cdprhost.motion.direct import to_wire
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.program import read_items
from cdprhost.motion.segments import SegmentBatch
from cdprhost.preflight.run import preflight, preflight_items
from cdprhost.profile.models import MachineProfile

POLL_S = 0.05
PROGRESS_EVERY_S = 0.1
STATUS_EVERY_S = 0.5


@dataclass
class PrintOptions:
    resume_from_layer: int | None = None
    log_path: str | Path | None = None
    resume_dir: str | Path | None = None
    idle_timeout_s: float = 30.0  # longest the device may show no progress while it should move
    batch_moves: int = (
        1024  # planner chunk: small enough to keep the device queue fed from the start
    )


@dataclass
class PrintResult:
    status: str
    segments: int = 0
    retransmits: int = 0
    final_steps: list[int] | None = None
    last_line: int | None = None
    last_layer: int | None = None
    print_time_s: float = 0.0
    estimated_time_s: float = 0.0
    violations: list[dict[str, Any]] = field(default_factory=list)
    reason: str = ""
    resume_file: str | None = None

    @property
    def exit_code(self) -> int:
        return 0 if self.status == "completed" else 1

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items()}


class _Stop(Exception):
    """Internal: leave the streaming loop at a rest point (cancel)."""


class PrintJob:
    def __init__(
        self,
        gcode: str | Path,
        profile: MachineProfile,
        link_factory: Callable[[], HostLink],
        options: PrintOptions | None = None,
        on_event: Callable[[Event], None] | None = None,
    ):
        self.gcode = Path(gcode)
        self.profile = profile
        self.model = MachineModel.from_profile(profile)
        self.link_factory = link_factory
        self.options = options or PrintOptions()
        self.on_event = on_event or (lambda e: None)
        self.log = JobLog(self.options.log_path)
        self._requests: set[str] = set()
        self._lock = threading.Lock()
        self._state = JobState.IDLE
        self.link: HostLink | None = None
        self._map = SegmentMap()
        self._last_progress = 0.0
        self._last_status = 0.0
        self._t0_device = 0.0
        self._waiting_heat_item = 0
        self._status: DeviceStatus | None = None
        self._at_rest = True  # does the queued motion end at rest?

    # ------------------------------------------------------------ requests
    def request_pause(self) -> None:
        self._request("pause")

    def request_resume(self) -> None:
        self._request("resume")

    def request_cancel(self) -> None:
        self._request("cancel")

    def _request(self, what: str) -> None:
        with self._lock:
            self._requests.add(what)
        self.log.write("request", what=what)

    def _take(self, what: str) -> bool:
        with self._lock:
            if what in self._requests:
                self._requests.discard(what)
                return True
            return False

    @property
    def state(self) -> JobState:
        return self._state

    # -------------------------------------------------------------- events
    def _emit(self, event: Event) -> None:
        if isinstance(event, StateChanged):
            self._state = event.state
        self.log.event(event)
        self.on_event(event)

    def _set(self, state: JobState, reason: str = "") -> None:
        if state is not self._state:
            self._emit(StateChanged(state, reason))

    # ------------------------------------------------------------ the job
    def _items(self):
        items = read_items(self.gcode, self.profile, self.model)
        if self.options.resume_from_layer is not None:
            z_max = self.profile.build_volume.z_max_mm - self.profile.build_volume.bed_origin[2]
            items = from_layer(items, self.options.resume_from_layer, z_max=z_max)
        return items

    def run(self) -> PrintResult:
        try:
            return self._run()
        finally:
            self.log.close()

    def _run(self) -> PrintResult:
        self._set(JobState.PREFLIGHT, str(self.gcode))
        try:
            if self.options.resume_from_layer is None:
                report = preflight(self.gcode, self.profile, self.model)
            else:
                report = preflight_items(
                    self._items(), self.profile, self.model, source=str(self.gcode)
                )
        except GcodeError as exc:
            self._set(JobState.REFUSED, str(exc))
            return PrintResult(
                "refused",
                reason=str(exc),
                last_line=exc.line,
                violations=[
                    {"line": exc.line, "rule": "syntax", "point": None, "detail": exc.reason}
                ],
            )
        self._emit(
            Planned(report.layers, report.moves, report.estimated_time_s, report.filament_mm)
        )
        if not report.ok:
            first = report.violations[0]
            self._set(
                JobState.REFUSED, f"preflight: line {first.line}: {first.rule}: {first.detail}"
            )
            return PrintResult(
                "refused",
                violations=[v.model_dump() for v in report.violations],
                estimated_time_s=report.estimated_time_s,
                reason=self._state_reason(report),
            )
        result = PrintResult("failed", estimated_time_s=report.estimated_time_s)
        try:
            self.link = self.link_factory()
            self._t0_device = self._device_time()
            self._stream(result)
            self._finish(JobState.DONE, "completed", result)
        except _Stop:
            self._cancel_tail(result)
        except LinkError as exc:
            self._fail(result, f"{type(exc).__name__}: {exc}", getattr(exc, "last_segment", None))
        except GcodeError as exc:  # cannot happen after a clean preflight, but never lose it
            self._fail(result, str(exc))
        return result

    @staticmethod
    def _state_reason(report) -> str:
        v = report.violations[0]
        return (
            f"{report.violations_total} violation(s); first at line {v.line}: {v.rule}: {v.detail}"
        )

    # ---------------------------------------------------------- streaming
    def _stream(self, result: PrintResult) -> None:
        link = self.link
        assert link is not None
        clock = link.identity.clock_hz
        self._set(JobState.PRINTING)
        planned = segment_program(
            self._items(),
            self.profile,
            self.model,
            clock_hz=clock,
            batch_moves=self.options.batch_moves,
        )
        ahead = Prefetch(planned)
        ahead.wait_filled(4)
        for out in ahead:
            if isinstance(out, SegmentBatch):
                self._send_segments(out)
            else:
                self._send_command(out)
        self._drain()

    def _send_segments(self, batch: SegmentBatch) -> None:
        link = self.link
        i, n = 0, len(batch)
        while i < n:
            self._service()
            stopping = self._stop_wanted()
            free = link.progress.queue_free
            if free <= 0:
                link.poll(POLL_S)
                continue
            j = min(n, i + max(1, free))
            if stopping:
                rest = first_rest_index(batch, i)
                if rest is not None and rest < j:
                    j = rest + 1
            sub = _slice(batch, i, j)
            numbers = link.queue_segments(to_wire(sub))
            self._map.add(numbers.start, sub)
            i = j
            self._at_rest = bool(sub.v_end[-1] <= 1e-9)
            if stopping and self._at_rest:
                self._hold_at_rest()

    def _send_command(self, item: Any) -> None:
        msgs = device_messages(
            item,
            model=self.model,
            home_mm=self.profile.drive.home_mm,
            clock_hz=self.link.identity.clock_hz,
        )
        if isinstance(item, g.Message):
            self._emit(Notice(f"line {item.line}: {item.text}"))
        if not msgs:
            return
        numbers = self.link.send(*msgs)
        if isinstance(item, g.SetTemperature) and item.wait and item.target_c > 0:
            self._waiting_heat_item = max(numbers)
            self._set(
                JobState.HEATING, f"line {item.line}: waiting for {item.heater} {item.target_c:g} C"
            )
        if (
            self._stop_wanted() and self._at_rest
        ):  # mid-motion commands wait for the next rest point
            self._hold_at_rest()

    # ------------------------------------------------------- pause/cancel
    def _stop_wanted(self) -> bool:
        with self._lock:
            return bool(self._requests & {"pause", "cancel"})

    def _hold_at_rest(self) -> None:
        """At a rest point: drain the queue, then pause (until resumed) or stop (cancel)."""
        with self._lock:
            cancel = "cancel" in self._requests
        self._set(JobState.CANCELLING if cancel else JobState.PAUSING)
        self._drain()
        if cancel or self._take("cancel"):
            raise _Stop
        self._take("pause")
        self._set(JobState.PAUSED, "at rest; heaters kept")
        while True:
            self._service(force_status=False)
            if self._take("cancel"):
                self._set(JobState.CANCELLING)
                raise _Stop
            if self._take("resume"):
                self._set(JobState.PRINTING)
                return
            self.link.poll(POLL_S)

    def _drain(self) -> None:
        link = self.link
        last, since = -1, time.monotonic()
        while link.progress.items_done < link.items_sent or link.progress.moving:
            link.poll(POLL_S)
            self._service()
            done = link.progress.items_done
            if done != last:
                last, since = done, time.monotonic()
            elif (
                time.monotonic() - since > self.options.idle_timeout_s
                and self._state is not JobState.HEATING
            ):
                raise LinkError(
                    f"the device made no progress for {self.options.idle_timeout_s:g} s"
                )
        self._service(force_status=True)

    # -------------------------------------------------------- observation
    def _device_time(self) -> float:
        st = self.link.request_status()
        return st.motion_time_s

    def _service(self, force_status: bool = False) -> None:
        link = self.link
        for ev in link.poll(0.0):
            if isinstance(ev, DeviceErrorEvent):
                raise LinkError(f"device error {ev.name} (item {ev.item})")
            if isinstance(ev, DeviceStatus):
                self._on_status(ev)
        now = time.monotonic()
        if force_status or now - self._last_status > STATUS_EVERY_S:
            self._last_status = now
            self._on_status(link.request_status())
        if self._state is JobState.HEATING and link.progress.items_done >= self._waiting_heat_item:
            self._set(JobState.PRINTING)
        if force_status or now - self._last_progress > PROGRESS_EVERY_S:
            self._last_progress = now
            self._progress()

    def _on_status(self, st: DeviceStatus) -> None:
        self._status = st
        self._emit(Temperatures(st.hotend_c, st.bed_c, st.hotend_target_c, st.bed_target_c))
        c = self.link.counters
        self._emit(LinkHealth(c.retransmits, c.bad_frames + st.device_bad_frames, c.naks_received))

    def _progress(self) -> None:
        info = self._map.lookup(self.link.progress.segments_done)
        if info is None:
            return
        p = np.asarray(info.point)[None, :]
        t = tensions(p, self.model.geometry.outlets, self.model.statics)[0]
        sliders = self.model.sliders_from_steps(np.asarray(info.steps[:3]))
        self._emit(
            Progress(
                self.link.progress.segments_done,
                info.line,
                info.layer,
                info.t_end_s,
                info.point,
                tuple(float(v) for v in sliders),
                tuple(float(v) for v in t),
                info.steps,
            )
        )

    # ------------------------------------------------------------- endings
    def _finish(self, state: JobState, status: str, result: PrintResult) -> None:
        link = self.link
        st = link.request_status()
        info = self._map.lookup(link.progress.segments_done)
        result.status = status
        result.segments = link.progress.segments_done
        result.retransmits = link.counters.retransmits
        result.final_steps = list(st.steps)
        result.last_line = info.line if info else None
        result.last_layer = info.layer + 1 if info else None
        result.print_time_s = round(st.motion_time_s - self._t0_device, 6)
        self._progress()
        self._set(state, status)

    def _cancel_tail(self, result: PrintResult) -> None:
        if self.profile.heaters.on_cancel == "off":
            self.link.send(*heaters_off())
        self._drain()
        self._finish(JobState.CANCELLED, "cancelled", result)

    def _fail(self, result: PrintResult, reason: str, last_segment: int | None = None) -> None:
        """``last_segment``: the last executed segment when the error knows it (a device reset)."""
        link = self.link
        done = link.progress.segments_done if link else 0
        info = self._map.lookup(last_segment if last_segment else done)
        result.status, result.reason = "failed", reason
        result.segments = done
        result.retransmits = link.counters.retransmits if link else 0
        result.last_line = info.line if info else None
        result.last_layer = info.layer + 1 if info else None
        result.final_steps = list(info.steps) if info else None
        if link and self.profile.heaters.on_failure == "off":
            try:
                link.clear_fault(timeout=1.0)
                link.send(*heaters_off(), timeout=1.0)
            except (LinkError, OSError):
                pass  # link lost: the firmware's own watchdog must turn heaters off
        st = self._status
        point = ResumePoint(
            str(self.gcode),
            reason,
            result.last_line,
            result.last_layer,
            info.point if info else None,
            info.steps if info else None,
            st.hotend_target_c if st else 0.0,
            st.bed_target_c if st else 0.0,
            max(result.last_layer or 1, 1),
        )
        try:
            result.resume_file = str(
                point.save(resume_path_for(self.gcode, self.options.resume_dir))
            )
        except OSError:
            result.resume_file = None
        # the event carries the 0-based layer index, like Progress; the JSON result is 1-based
        self._emit(
            Failure(
                reason,
                result.last_line,
                info.layer if info else None,
                info.point if info else None,
                result.resume_file,
            )
        )
        self._set(JobState.FAILED, reason)


def _slice(batch: SegmentBatch, i: int, j: int) -> SegmentBatch:
    return SegmentBatch(*(getattr(batch, f)[i:j] for f in batch.__dataclass_fields__))
