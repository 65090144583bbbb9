"""The print job: preflight, connect and check the device, stream, and end safely.

Imperative shell around the pure pipeline (``cdprhost.motion.pipeline``), the machine
(``cdprhost.machine``) and the streamer (:mod:`cdprhost.job.streamer`, which holds the
link once connected). ``run()`` blocks; pause/resume/cancel requests come from other
threads. Every way a job ends is safe:

- completed: only when the device reports the last segment executed; the resume point
  is removed;
- cancelled (the operator, quit, a signal) or stopped safely (the job log): a controlled
  stop within the motion sent (:mod:`~cdprhost.job.stopping`), park, heaters off, resume point;
- any other failure (link lost, device fault, a bug): the host gives up with an
  emergency stop first (motors kept, heaters off unless the profile keeps them), then
  saves the resume point naming the exact last segment the device executed.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from cdprhost.errors import CdprError
from cdprhost.gcode.errors import GcodeError
from cdprhost.job.board import announced_record
from cdprhost.job.exact import ExactPlaceUnknown, device_stop, refine_point, reset_notice
from cdprhost.job.log import JobLog
from cdprhost.job.options import PrintOptions, PrintResult, violations_reason
from cdprhost.job.overriding import OverrideRequests, requested_text, resumed_text
from cdprhost.job.prefetch import Prefetch
from cdprhost.job.resume import (
    ResumeWriter,
    file_sha256,
    remove_resume_point,
    resume_path_for,
    resume_setup,
)
from cdprhost.job.resume_items import PlanSpec
from cdprhost.job.state import Event, Failure, JobState, Notice, Planned, StateChanged
from cdprhost.job.stopping import Stop, StopRecord
from cdprhost.job.streamer import Requests, StreamContext, Streamer
from cdprhost.kinematics.machine import MachineModel
from cdprhost.link import DeviceReset, DeviceStatus, HostLink, LinkError
from cdprhost.link.events import DeviceCaps as AnnouncedCaps
from cdprhost.link.events import Identity
from cdprhost.machine import DeviceNotReady, Machine, prepare_device
from cdprhost.machine.board_limits import board_caps
from cdprhost.machine.commands import estop_flags, heaters_off
from cdprhost.motion.device_limits import same_board_plan
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.prepared import Prepared, prepare
from cdprhost.motion.segments import DEFAULT_LIMITS
from cdprhost.preflight.run import preflight_prepared
from cdprhost.profile.device_record import DeviceRecord
from cdprhost.profile.models import MachineProfile

log = logging.getLogger(__name__)

__all__ = ["PrintJob", "PrintOptions", "PrintResult"]


class _CancelledEarly(Exception):
    """A cancel arrived before anything moved."""


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
        self._plan_profile = profile  # capped to the device's step rate once connected
        self._segment_limits = DEFAULT_LIMITS  # the device's, once connected
        self.model = MachineModel.from_profile(profile)
        self.link_factory = link_factory
        self.options = options or PrintOptions()
        self.on_event = on_event or (lambda e: None)
        self.log = JobLog(self.options.log_path)
        self.requests = Requests()
        self.overrides = OverrideRequests()  # M220 / M221
        self._state = JobState.IDLE
        self._done = threading.Event()  # run() has returned
        self._started = False
        self.link: HostLink | None = None  # set once connected (the streamer holds it)
        self._streamer: Streamer | None = None
        self._sha256 = ""
        self._prepared: Prepared | None = None
        self._t0 = 0.0  # the device's motion clock when streaming began
        self.plan = self._plan_spec()
        point = self.options.resume
        # --resume rebuilds the saved job's program: its placement options, not new ones
        self.setup = (
            self.options.setup if point is None else resume_setup(point, self.options.setup)
        )

    # ------------------------------------------------------------ requests
    def request_pause(self) -> None:
        self._request("pause")

    def request_resume(self) -> None:
        self._request("resume")

    def request_cancel(self, reason: str = "") -> None:
        """Stop within the buffered motion, park and end CANCELLED (``reason``: who asked, e.g.
        "quit" or "SIGTERM"; recorded in the final state)."""
        if reason:
            self.requests.cancel_reason = self.requests.cancel_reason or reason
        self._request("cancel")

    def request_speed(self, percent: float) -> None:
        """M220 S<percent> while printing: the speeds of what is not sent yet (within about
        the device's buffered second); ValueError outside 10-500 %."""
        self._override("speed", percent)

    def request_flow(self, percent: float) -> None:
        """M221 S<percent> while printing: the extrusion of what is not sent yet."""
        self._override("flow", percent)

    def _override(self, what: str, percent: float) -> None:
        factor = self.overrides.set(what, percent)
        self.log.write("request", what=what, percent=round(factor * 100, 3))
        if self._started and not self._done.is_set():
            self._emit(Notice(requested_text(what, factor)))

    def emergency_stop(self) -> bool:
        """ESTOP now (motors kept, heaters off unless the profile keeps them on failure); the
        job ends FAILED. True when the device acknowledged (False without a link)."""
        self._emit(Notice("emergency stop requested"))
        self.log.write("request", what="estop")
        self.requests.add("estop")
        link = self.link
        if link is None or self._done.is_set():
            return False
        try:
            return bool(link.emergency_stop(timeout=1.0, flags=estop_flags(self.profile)))
        except (LinkError, OSError) as exc:
            log.warning("emergency stop not acknowledged: %s", exc)
            return False

    @property
    def last_stop(self) -> StopRecord | None:
        """The last controlled stop (pause or cancel): its device segments and speeds."""
        return self._streamer.stops.record if self._streamer is not None else None

    @property
    def finished(self) -> bool:
        """``run()`` has returned (the machine is left safe, the result is final)."""
        return self._done.is_set()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Until ``run()`` has returned (True) or ``timeout_s`` passed (False)."""
        if not self._started:
            return True
        return self._done.wait(timeout_s)

    def shutdown(self, reason: str = "quit", timeout_s: float = 10.0) -> bool:
        """Quit and signals: cancel (stop, park, heaters off, resume point) and wait until the
        job has ended; an e-stop when it has not within ``timeout_s``. Close the link only after
        this returns."""
        self.request_cancel(reason)  # before the start too: the job then ends at once
        if not self._started or self._done.is_set():
            return True
        if self._done.wait(timeout_s):
            return True
        log.warning("the job did not stop within %g s: emergency stop", timeout_s)
        self.emergency_stop()
        return self._done.wait(2.0)

    def _request(self, what: str) -> None:
        """Recorded when asked (a Notice and the job log); the state changes when it acts."""
        self.requests.add(what)
        self.log.write("request", what=what)
        if self._started and not self._done.is_set():
            self._emit(Notice(f"{what} requested ({self._state.value})"))

    @property
    def state(self) -> JobState:
        return self._state

    # -------------------------------------------------------------- events
    def _emit(self, event: Event) -> None:
        if isinstance(event, StateChanged):
            self._state = event.state
            log.info(
                "job %s: %s%s",
                self.gcode.name,
                event.state.value,
                f" ({event.reason})" if event.reason else "",
            )
        self.log.event(event)
        self.on_event(event)

    def _set(self, state: JobState, reason: str = "") -> None:
        if state is not self._state:
            self._emit(StateChanged(state, reason))

    # ------------------------------------------------------------ the program
    def _plan_spec(self) -> PlanSpec:
        point = self.options.resume
        if point is not None:
            if not point.exact:
                raise CdprError(f"{point.gcode}: the resume point names no position to resume at")
            return PlanSpec("point", line=point.last_line, point=point.point, e_mm=point.e_mm)
        if self.options.resume_from_layer is not None:
            return PlanSpec("layer", layer=self.options.resume_from_layer)
        return PlanSpec()

    def _prepare(self) -> Prepared:
        if self._prepared is None:
            # the job's own copy: the preflight and the print read the same bytes
            prepared = prepare(self.gcode, self.profile, self.model, self.setup, copy=True)
            point = self.options.resume
            if point is not None and point.placement is not None:
                saved = (float(point.placement[0]), float(point.placement[1]))
                if max(abs(a - b) for a, b in zip(saved, prepared.placement)) > 1e-6:
                    raise CdprError(
                        f"{self.gcode}: --resume: the placement options "
                        f"{self.setup.options()!r} now shift the part by "
                        f"{prepared.placement[0]:.3f},{prepared.placement[1]:.3f} mm, the "
                        f"interrupted print by {saved[0]:.3f},{saved[1]:.3f} mm (another "
                        "profile?); resume from a layer instead"
                    )
            self._prepared = prepared
        return self._prepared

    def _items(self, plan: PlanSpec | None = None) -> Iterable[Any]:
        items = self._prepare().items()
        z_max = self.profile.build_volume.z_max_mm - self.profile.build_volume.bed_origin[2]
        return (plan or self.plan).apply(items, z_max=z_max)

    # ------------------------------------------------------------ the job
    def run(self) -> PrintResult:
        self._started = True
        try:
            return self._run()
        finally:
            self._drop_copy()
            self.log.close()
            self._done.set()

    def _drop_copy(self) -> None:
        """The job's copy of its file goes with the job (a later read copies it again)."""
        prepared, self._prepared = self._prepared, None
        if prepared is not None and prepared.copy is not None:
            prepared.copy.remove()

    def _run(self) -> PrintResult:
        self._set(JobState.PREFLIGHT, str(self.gcode))
        try:
            prepared = self._prepare()
            self._sha256 = prepared.sha256 or file_sha256(self.gcode)
            report, planned = self._estimate(prepared)
        except _CancelledEarly:
            return self._cancelled_early()
        except GcodeError as exc:
            self._set(JobState.REFUSED, str(exc))
            return PrintResult.syntax_refusal(exc)
        except (CdprError, OSError) as exc:
            reason = (
                str(exc) if isinstance(exc, CdprError) else f"{self.gcode}: {exc.strerror or exc}"
            )
            self._set(JobState.REFUSED, reason)
            return PrintResult("refused", reason=reason)
        self._emit(planned)
        if not report.ok:
            first = report.violations[0]
            self._set(
                JobState.REFUSED, f"preflight: line {first.line}: {first.rule}: {first.detail}"
            )
            return PrintResult(
                "refused",
                violations=[v.model_dump() for v in report.violations],
                estimated_time_s=report.estimated_time_s,
                reason=violations_reason(report),
            )
        result = PrintResult("failed", estimated_time_s=report.estimated_time_s)
        self._say_board(report, result)
        if self.requests.has("cancel", "estop"):
            return self._cancelled_early()
        if self.log.problem:  # nothing has moved: say so and stop here
            self._fail_early(result, f"{self.log.problem}; nothing moved")
            return result
        try:
            link = self.link_factory()
        except LinkError as exc:  # a failed connect never touches the resume point
            result.bad_input = exc.exit_code == 2
            self._fail_early(result, str(exc) or "cannot connect to the device")
            return result
        except OSError as exc:
            self._fail_early(result, f"cannot open the device: {exc.strerror or exc}")
            return result
        self.link = link
        self._print(link, result)
        return result

    def _unless_cancelled(self, items: Iterable[Any]) -> Iterator[Any]:
        """``items``, until a cancel (a signal, quit) ends the preflight: nothing has moved."""
        for item in items:
            if self.requests.has("cancel", "estop"):
                raise _CancelledEarly
            yield item

    def _cancelled_early(self) -> PrintResult:
        if self.requests.has("estop"):
            # an e-stop ends a job FAILED wherever it comes (the device is left stopped
            # and needs a reset), the preflight included
            result = PrintResult("failed")
            self._fail_early(result, "emergency stop before anything moved")
            return result
        self._set(JobState.CANCELLED, "cancelled before anything moved")
        return PrintResult("cancelled", reason=self.requests.cancel_reason)

    def _estimate(
        self, prepared: Prepared, device: DeviceRecord | None = None
    ) -> tuple[Any, Planned]:
        """Preflight and the totals to show, on the board's limits: ``device`` as it
        announced them, or else the profile's record."""
        resumed = self.plan.start != "file"
        items = self._items() if resumed else prepared.items()
        report = preflight_prepared(prepared, self._unless_cancelled(items), device=device)
        return report, self._planned(prepared, report, resumed, device)

    def _say_board(self, report: Any, result: PrintResult) -> None:
        """A notice when the board slows the print against the profile's own limits."""
        if report.board is not None and report.board.message:
            self._emit(Notice(report.board.message))
            result.notices.append(report.board.message)
            result.board = report.board.message

    def _replan_for(
        self, ident: Identity | None, caps: AnnouncedCaps | None, result: PrintResult
    ) -> None:
        """Once connected: the estimate again when the board announced other limits than the
        profile's record (the progress display and ETA follow), and the record kept."""
        announced = announced_record(ident, caps)
        if announced is None or announced.same_limits(self.profile.device):
            return
        if self.options.record_device is not None:
            try:
                self.options.record_device(announced)
            except (CdprError, OSError) as exc:  # the print goes on; the next estimate guesses
                log.warning("the board's limits were not recorded: %s", exc)
        record = self.profile.device
        if same_board_plan(self.profile, announced, record):
            return
        report, planned = self._estimate(self._prepare(), announced)
        self._emit(planned)
        result.estimated_time_s = report.estimated_time_s
        self._say_board(report, result)

    def _planned(
        self, prepared: Prepared, report: Any, resumed: bool, device: DeviceRecord | None = None
    ) -> Planned:
        """Totals to show; a resumed job counts its progress from where the file restarts."""
        layers, done = report.layers, 0.0
        if resumed:  # the whole file once more, for its totals
            whole = preflight_prepared(
                prepared, self._unless_cancelled(prepared.items()), device=device
            )
            layers = whole.layers
            done = max(0.0, whole.estimated_time_s - report.estimated_time_s)
        return Planned(
            layers, report.moves, report.estimated_time_s, report.filament_mm, done_s=done
        )

    def _fail_early(self, result: PrintResult, reason: str) -> None:
        result.status, result.reason = "failed", reason
        self._emit(Failure(reason, None, None))
        self._set(JobState.FAILED, reason)

    def _print(self, link: HostLink, result: PrintResult) -> None:
        machine = Machine(link, self.profile, self.model)
        streamer: Streamer | None = None
        try:
            check = prepare_device(machine, clear_fault=self.options.clear_fault)
            ident, dev_caps = link.identity, link.caps
            caps = board_caps(link, self.profile)
            self._plan_profile = caps.profile
            self._segment_limits = caps.segments
            for text in [*check.notices, *([caps.notice] if caps.notice else [])]:
                self._emit(Notice(text))
                result.notices.append(text)
            reset = reset_notice(link.boot)
            for text in [reset] if reset else []:
                self._emit(Notice(text))
                result.notices.append(text)
            self._replan_for(ident, dev_caps, result)
            self._refine_resume(link, check.found, result)
            self._say_overrides_reset(result)
            self._t0 = link.request_status().motion_time_s
            writer = ResumeWriter(
                resume_path_for(self.gcode, self.options.resume_dir, self._sha256),
                self.options.resume_every_s,
                self.options.resume_layer_s,
            )
            streamer = Streamer(link, self._context(), writer)
            self._streamer = streamer
            self._set(JobState.PRINTING)
            planned = segment_program(
                self._items(),
                self._plan_profile,
                self.model,
                clock_hz=streamer.clock_hz,
                limits=self._segment_limits,
                batch_moves=self.options.batch_moves,
            )
            ahead = Prefetch(planned)
            ahead.wait_filled(4)
            streamer.run(ahead)
            self._finish(streamer, result, JobState.DONE, "completed")
            remove_resume_point(self.gcode, self.options.resume_dir, self._sha256)
        except (DeviceNotReady, ExactPlaceUnknown) as exc:
            self._set(JobState.REFUSED, str(exc))
            result.status, result.reason = "refused", str(exc)
        except Stop as stop:
            assert streamer is not None
            self._stop_tail(streamer, result, stop.reason)
        except LinkError as exc:
            # the operator reads it: the link's words (port, what happened), no class name
            self._give_up(link, streamer, result, str(exc) or "the link failed", exc)
        except (CdprError, GcodeError) as exc:
            self._give_up(link, streamer, result, str(exc), exc)
        except Exception as exc:  # a bug: stopped like a cancel when the link allows, else e-stop
            log.exception("print job failed unexpectedly")
            why = f"internal error: {type(exc).__name__}: {exc}"
            if streamer is not None and streamer.stops.stop_after_bug(why):
                self._stop_tail(streamer, result, why)
            else:
                self._give_up(link, streamer, result, why, exc)

    def _say_overrides_reset(self, result: PrintResult) -> None:
        """A resumed print that ran with a speed or flow override starts again at 100 %."""
        point = self.options.resume
        if point is None:
            return
        text = resumed_text((point.speed_pct, point.flow_pct), self.overrides.factors())
        if text is None:
            return
        self._emit(Notice(text))
        result.notices.append(text)

    def _refine_resume(self, link: HostLink, found: DeviceStatus, result: PrintResult) -> None:
        """``--resume`` after a killed host: the device's own last segment, when it knows it
        (still faulted on the same boot, or kept through a reset and announced in BOOT);
        refused (ExactPlaceUnknown, before anything moves) when the device restarted since
        and kept no record."""
        point = self.options.resume
        if point is None or link.identity is None:
            return
        stop = device_stop(point, found, link.identity.boot_id, link.boot)
        if stop is None:
            return
        exact = refine_point(
            point,
            stop.segment,
            self._items,
            self._plan_profile,
            self.model,
            clock_hz=link.identity.clock_hz,
            batch_moves=self.options.batch_moves,
            limits=self._segment_limits,
        )
        kept = " (its record kept through the reset)" if stop.reset else ""
        if exact is None:
            if stop.reset:
                raise ExactPlaceUnknown(
                    f"--resume: the device's record kept through the reset names segment "
                    f"{stop.segment}, which is not on the program of the resume point: the "
                    "exact place is unknown; restart from a layer with --resume-from-layer"
                )
            return
        if exact.device_segment == point.device_segment:
            text = f"the resume point is the device's last executed segment{kept}"
        else:
            text = (
                f"the device executed {exact.device_segment - point.device_segment} segments "
                f"after the resume point was saved{kept}: resuming at line {exact.last_line} "
                "instead"
            )
        self._emit(Notice(text))
        result.notices.append(text)
        self.plan = PlanSpec("point", line=exact.last_line, point=exact.point, e_mm=exact.e_mm)

    def _context(self) -> StreamContext:
        return StreamContext(
            gcode_path=str(self.gcode.resolve()),
            sha256=self._sha256,
            profile=self.profile,
            model=self.model,
            plan=self.plan,
            emit=self._emit,
            state=lambda: self._state,
            requests=self.requests,
            overrides=self.overrides,
            log_problem=lambda: self.log.problem,
            idle_timeout_s=self.options.idle_timeout_s,
            setup=self.setup,
            placement=self._prepare().placement,
            plan_profile=self._plan_profile,
            limits=self._segment_limits,
        )

    # ------------------------------------------------------------- endings
    def _finish(
        self, streamer: Streamer, result: PrintResult, state: JobState, status: str
    ) -> None:
        st = streamer.link.request_status()
        streamer.fill(result)
        result.status = status
        result.final_steps = list(st.steps)
        result.print_time_s = round(st.motion_time_s - self._t0, 6)
        streamer.service(force_status=True)
        self._set(state, status)

    def _stop_tail(self, streamer: Streamer, result: PrintResult, reason: str) -> None:
        """Stopped at rest after a cancel or a safe stop: park (``park.on_cancel``), heaters
        off (``heaters.on_cancel``; always when the host quits or the stop is a failure),
        resume point, end."""
        link = streamer.link
        quitting = self.requests.cancel_reason
        try:
            machine = Machine(link, self.profile, self.model)
            park = self.profile.park
            if park.on_cancel and park.lift_mm > 0 and not streamer.stops.parked:
                machine.park(lift_mm=park.lift_mm)
            if reason or quitting or self.profile.heaters.on_cancel == "off":
                link.send(*heaters_off())
            streamer.drain(final=False)
        except LinkError as exc:
            self._give_up(link, streamer, result, f"{reason or 'cancelled'}; then {exc}", exc)
            return
        self._save_point(streamer, result, reason or "cancelled")
        if reason:
            streamer.fill(result)
            result.status, result.reason = "failed", reason
            self._failed(streamer, result, reason)
            return
        result.reason = quitting
        self._finish(
            streamer,
            result,
            JobState.CANCELLED,
            "cancelled" + (f": {quitting}" if quitting else ""),
        )
        result.status = "cancelled"

    def _give_up(
        self,
        link: HostLink,
        streamer: Streamer | None,
        result: PrintResult,
        reason: str,
        exc: BaseException,
    ) -> None:
        """Emergency stop first, then name the exact last executed segment and save it."""
        if not isinstance(exc, DeviceReset):
            try:
                link.emergency_stop(timeout=1.0, flags=estop_flags(self.profile))
            except (LinkError, OSError) as stop_exc:  # the device's watchdog stops it
                log.warning("emergency stop not acknowledged: %s", stop_exc)
        result.status, result.reason = "failed", reason
        if streamer is None:
            self._emit(Failure(reason, None, None))
            self._set(JobState.FAILED, reason)
            return
        last = exc.last_segment if isinstance(exc, DeviceReset) else None
        streamer.fill(result, last)
        self._save_point(streamer, result, reason, last)
        self._failed(streamer, result, reason, last)

    def _failed(
        self, streamer: Streamer, result: PrintResult, reason: str, last: int | None = None
    ) -> None:
        """The machine time printed, the Failure event and the final state."""
        result.print_time_s = streamer.print_time(last)
        info = streamer.executed(last)
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

    def _save_point(
        self, streamer: Streamer, result: PrintResult, reason: str, last: int | None = None
    ) -> None:
        """The final point, when the job executed something (else the last one stays)."""
        info = streamer.executed(last)
        path = resume_path_for(self.gcode, self.options.resume_dir, self._sha256)
        if info is None:
            result.resume_file = str(path) if path.exists() else None
            return
        try:
            result.resume_file = str(streamer.point(reason, info).save(path))
        except OSError as exc:
            log.warning("resume point %s not written: %s", path, exc.strerror or exc)
            result.resume_file = str(path) if path.exists() else None
