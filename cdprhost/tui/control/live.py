"""The UI backend on the real layers: host link, print job, preflight, machine operations,
calibration and diagnosis.

Every method that talks to the device or computes runs in a worker thread (see
:mod:`cdprhost.tui.control.backend`); the link itself is thread-safe. While a
print runs, the job owns the link: the UI only reads its counters.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.job.state import LinkHealth
from cdprhost.kinematics import MachineModel
from cdprhost.machine import Machine, NotHomed
from cdprhost.machine.prepare import describe_fault, fault_clearable
from cdprhost.profile import MachineProfile, load_profile
from cdprhost.tui.control.backend import EMBEDDED, CalibrationBackend, EventSink, JobHandle
from cdprhost.tui.control.live_calibration import LiveCalibration
from cdprhost.tui.control.live_diagnosis import DiagnosedProfile
from cdprhost.tui.control.views import (
    ConsoleLine,
    DeviceStatusView,
    DiagnosisView,
    PortChoice,
    PreflightView,
    ResumeView,
    ViolationRow,
)

ALL_MODULES = 0b111
JOG_SPEED_MM_S = 40.0
DEVICE_LOG = 200
BUSY_STATUS_MAX_AGE_S = 2.0  # older while busy: not shown as fresh (the screens mark it stale)
DEVICE_RECORD_KEEP = 4096
"""Executed segments the embedded simulated device holds in memory (at most an eighth more):
the newest, enough for an observer's motion directions (its window is 4096). Without a cap
its record grew by 64 bytes a segment for as long as the UI ran (65 KB per print of the
memory bench's small part; 32 MB for a print of half a million segments)."""


def device_status_view(model: Any, st: Any, fault: str, clearable: bool) -> DeviceStatusView:
    """A status report of the device as the screens show it (the position by ``model``'s
    forward kinematics, once homed). ``st`` is the link's status or the printer service's
    (the same fields); ``fault`` in words ("" when none) and whether a host may clear it."""
    steps = (int(st.steps[0]), int(st.steps[1]), int(st.steps[2]), int(st.steps[3]))
    s = model.sliders_from_steps(np.asarray(steps[:3]))
    homed = st.homed_mask & ALL_MODULES == ALL_MODULES
    position = None
    if homed:
        p = model.fk(s[None, :])[0]
        position = (float(p[0]), float(p[1]), float(p[2])) if np.all(np.isfinite(p)) else None
    return DeviceStatusView(
        steps,
        (float(s[0]), float(s[1]), float(s[2])),
        position,
        st.hotend_c,
        st.bed_c,
        st.hotend_target_c,
        st.bed_target_c,
        bool(st.enabled_mask),
        homed,
        st.queue_free,
        fault,
        clearable,
    )


def identity_rows(
    identity: Any, port: str, baud: int, total_step_rate: int | None = None
) -> tuple[tuple[str, str], ...]:
    """The device identity as (key, value) rows for the connection screen, with the step
    budget its axes share when it announced one (STEP_BUDGET)."""
    rows = [
        ("port", port if port != EMBEDDED else "embedded simulated device (no hardware)"),
        ("firmware", f"{identity.firmware_name} {identity.firmware_version}"),
        ("protocol", ".".join(str(v) for v in identity.protocol)),
        ("axes", str(identity.axes)),
        ("queue capacity", f"{identity.queue_capacity} items"),
        ("clock", f"{identity.clock_hz:,} Hz"),
        ("max step rate", f"{identity.max_step_rate:,} steps/s"),
        *(
            [("step budget", f"{total_step_rate:,} steps/s, the axes summed")]
            if total_step_rate is not None
            else []
        ),
        ("heaters / fans", f"{identity.heaters} / {identity.fans}"),
        ("boot id", str(identity.boot_id)),
    ]
    if port != EMBEDDED:
        rows.insert(1, ("baud", str(baud)))
    return tuple(rows)


def preflight_view(report: Any, path: str, toolpath: Any = None) -> PreflightView:
    """A :class:`cdprhost.preflight.PreflightReport` as the print screen shows it."""
    violations = tuple(
        ViolationRow(v.line, v.rule, v.detail, tuple(v.point) if v.point is not None else None)
        for v in report.violations
    )
    notes = tuple(f"line {n.line}: {n.text}" for n in report.notes)
    return PreflightView(
        path,
        bool(report.ok),
        violations,
        int(report.moves),
        int(report.layers),
        float(report.estimated_time_s),
        float(report.filament_mm),
        notes,
        toolpath,
        placement_note(report),
    )


def placement_note(report: Any) -> str:
    """One short line: the shift applied and, for a part that does not fit, the offset
    that would (the CLI's report says more)."""
    from cdprhost.preflight.render import NO_FIT, offset_option, shift_text

    p = report.placement
    if p is None:
        return ""
    out = []
    if tuple(p.offset) != (0.0, 0.0):
        out.append(shift_text(p.offset))
    if not report.ok and p.allowed is not None:
        fit = p.fit_offset
        out.append(f"fits with {offset_option(fit)}" if fit is not None else NO_FIT)
    return " · ".join(out)


def refuse_if_served(port: str) -> None:
    """CdprError when a printer service holds ``port`` (this process must not open it)."""
    import socket

    from cdprhost.service.paths import files_for_port

    files = files_for_port(port)
    if not files.socket.exists():
        return
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(files.socket))
    except OSError:
        return  # a socket left behind: nobody listens
    finally:
        sock.close()
    pid = files.read_pid()
    raise CdprError(
        f"{port} is held by its printer service (pid {pid}): a print or another front end "
        "uses it; start `cdprhost tui` without --in-process to join it, or wait until it ends"
    )


class LiveBackend:
    """``sim_options`` go to :func:`cdprhost.sim.embedded.open_embedded` (faults, observer, config)."""

    def __init__(
        self,
        profile: str | MachineProfile,
        *,
        speedup: float | None = 10.0,
        sim_options: dict[str, Any] | None = None,
        diagnosis_settings: Any = None,
        job_options: dict[str, Any] | None = None,
        idle_pump_s: float = 0.0,
        setup: Any = None,
    ):
        from cdprhost.motion.prepared import Setup

        self.profile = load_profile(profile) if isinstance(profile, str) else profile
        self.profile_name = self.profile.name
        # what names the profile's file (a path or a name): a diagnosis writes its improvement
        self.profile_ref = profile if isinstance(profile, str) else self.profile.name
        self.model = MachineModel.from_profile(self.profile)
        self.speedup = speedup
        self.sim_options = dict(sim_options or {})
        self.diagnosis_settings = diagnosis_settings
        self.diagnosed = DiagnosedProfile()
        self.job_options = dict(job_options or {})
        self.idle_pump_s = idle_pump_s
        self.setup: Setup = setup or Setup()  # placement, --retarget, cancelled objects
        self._link: Any = None
        self.announced: Any = None  # a DeviceRecord a device announced elsewhere (its service)
        self._embedded = False
        self._where: tuple[str, int] | None = None
        self._identity: tuple[tuple[str, str], ...] = ()
        self._lock = threading.RLock()
        self._log: deque[ConsoleLine] = deque(maxlen=DEVICE_LOG)
        self.calibration: CalibrationBackend | None = LiveCalibration(self)

    # ---------------------------------------------------------------- link
    @property
    def link(self) -> Any:
        if self._link is None:
            raise CdprError("not connected: pick a port on the link screen")
        return self._link

    def ports(self) -> list[PortChoice]:
        from cdprhost.tui.control.ports import pty_choices, serial_choices

        speed = "as fast as possible" if not self.speedup else f"{self.speedup:g}x real time"
        embedded = PortChoice(
            EMBEDDED, "embedded simulated device", f"no hardware, {speed}", simulated=True
        )
        return [embedded, *pty_choices(), *serial_choices()]

    def connect(self, port: str, baud: int) -> tuple[tuple[str, str], ...]:
        from cdprhost.link import open_link
        from cdprhost.sim.embedded import open_embedded

        self.disconnect()
        if port == EMBEDDED:
            options = {"record_keep": DEVICE_RECORD_KEEP, **self.sim_options}
            link = open_embedded(
                speedup=self.speedup, timeout_s=self.profile.serial.timeout_s, **options
            )
            observer = self.sim_options.get("observer")
            if observer is not None and hasattr(observer, "attach_record"):
                observer.attach_record(
                    link.device.record
                )  # directions of motion for the truth's backlash
        else:
            refuse_if_served(port)
            link = open_link(port, baud, self.profile.serial.timeout_s)
        caps = link.caps
        rows = identity_rows(link.identity, port, baud, caps.total_step_rate if caps else None)
        with self._lock:
            self._link, self._embedded, self._where = link, port == EMBEDDED, (port, baud)
            self._identity = rows
        return rows

    def disconnect(self) -> None:
        with self._lock:
            link, self._link = self._link, None
        if link is not None:
            link.close()

    def connected(self) -> bool:
        return self._link is not None

    def machine_rate(self) -> float:
        return float(self.speedup) if self._embedded and self.speedup else 1.0

    def link_health(self) -> LinkHealth | None:
        link = self._link
        if link is None:
            return None
        c = link.counters
        return LinkHealth(retransmits=c.retransmits, bad_frames=c.bad_frames, naks=c.naks_received)

    def _note_events(self, events: list[Any]) -> None:
        from cdprhost.link import DeviceErrorEvent, DeviceEvent

        for ev in events:
            if isinstance(ev, DeviceErrorEvent):
                # the text starts with the name ("estop at item 2"): said once
                text = f"device error: {ev.text or ev.name}"
                self._log.append(ConsoleLine("error", text, time.time()))
            elif isinstance(ev, DeviceEvent):
                values = " ".join(str(v) for v in ev.values)
                self._log.append(ConsoleLine("device", f"{ev.name} {values}".strip(), time.time()))

    def device_log(self) -> list[ConsoleLine]:
        out = []
        while self._log:
            out.append(self._log.popleft())
        return out

    def device_status(self) -> DeviceStatusView | None:
        link = self._link
        if link is None:
            return None
        if link.lost is not None:  # a device that froze may be back: a new session, said
            said = link.recover()
            if said is None:
                raise link.lost
            self._log.append(ConsoleLine("notice", said, time.time()))
        # The embedded device lives on a virtual clock that only runs while the link is
        # pumped: keep it going between status requests (paced to the speed-up).
        pump = self.idle_pump_s * (self.speedup or 1.0) if self._embedded else 0.0
        self._note_events(link.poll(pump, fault_ok=True))  # a faulted device answers too
        return self._status_view(link.request_status())

    def status_while_busy(self) -> DeviceStatusView | None:
        link = self._link
        if link is None:
            return None
        link.ask_status()  # not a pump: the busy operation's own waiting reads the reply
        st = link.status()
        if st is None or link.now() - st.received_at > BUSY_STATUS_MAX_AGE_S:
            return None
        return self._status_view(st)

    def _status_view(self, st: Any) -> DeviceStatusView:
        return device_status_view(self.model, st, describe_fault(st) or "", fault_clearable(st))

    # --------------------------------------------------------------- print
    def preflight(self, path: str) -> PreflightView:
        from cdprhost.motion.prepared import prepare
        from cdprhost.preflight.run import preflight_prepared
        from cdprhost.tui.control.toolpath import ToolpathTap

        bed = self.profile.build_volume.bed_origin
        tap = ToolpathTap((float(bed[0]), float(bed[1]), float(bed[2])))
        prepared = prepare(path, self.profile, self.model, self.setup)
        report = preflight_prepared(prepared, tap.tap(prepared.items()), device=self._board())
        return preflight_view(report, path, tap.result())

    def _board(self) -> Any:
        """What the connected device announced (None: not connected): the estimate is for it."""
        from cdprhost.job.board import announced_record

        link = self._link
        return self.announced if link is None else announced_record(link.identity, link.caps)

    def toggle_center(self) -> bool:
        """Centre the part on the build volume (``--center``), or stop centring; returns
        whether it is centred now. The open file must be checked again."""
        from dataclasses import replace

        self.setup = replace(self.setup, center=not self.setup.center)
        return self.setup.center

    def find_resume(self, path: str) -> ResumeView | None:
        """The resume point the print job saved for ``path`` (same path and content), as the
        CLI finds it: exact (``--resume``) when it names a move, else a layer."""
        from cdprhost.job.resume import find_resume_point, resume_path_for, resume_question

        folder = self.job_options.get("resume_dir")
        saved = resume_path_for(path, folder)
        try:
            point = find_resume_point(path, folder)
        except (CdprError, OSError) as exc:
            return ResumeView(str(saved), path, "", 0, problem=str(exc))
        if point is None:
            return None  # none, or the file changed since (another program)
        name = Path(path).name
        at = saved.stat().st_mtime if saved.exists() else None
        problem = ""
        if point.exact:  # print --resume: at that very move
            layer = int(point.last_layer or 0)
            question = resume_question(name, point=point)
        else:  # print --resume-from-layer
            layer = int(point.suggested_layer or point.last_layer or 0)
            question = resume_question(name, layer=layer)
            if layer < 1:
                problem = "the stop was before the first layer: start again instead"
        return ResumeView(
            str(saved),
            point.gcode,
            point.reason,
            layer,
            point.last_line,
            at,
            problem,
            point.exact,
            question,
        )

    def make_job(
        self,
        path: str,
        on_event: EventSink,
        resume_from_layer: int | None = None,
        resume: bool = False,
        clear_fault: bool = False,
    ) -> JobHandle:
        try:
            from cdprhost.job.resume import find_resume_point
            from cdprhost.job.runner import PrintJob, PrintOptions
        except ImportError as exc:  # the runner is a separate piece of work
            raise CdprError(f"the print runner is not available: {exc}") from None
        self.link  # noqa: B018 - raises when not connected
        point = None
        if resume:  # the CLI's --resume: the saved point of this very file, found again now
            point = find_resume_point(path, self.job_options.get("resume_dir"))
            if point is None or not point.exact:
                raise CdprError(
                    f"{path}: no resume point for this file (it completed, or it changed since)"
                )
        options = PrintOptions(
            resume_from_layer=resume_from_layer,
            resume=point,
            setup=self.setup,
            clear_fault=clear_fault,
            **self.job_options,
        )
        return PrintJob(path, self.profile, self._job_link, options, on_event)

    def _job_link(self) -> Any:
        """The connected link; reconnected first when it has failed (after a device reset the
        link stays failed until a new session, and a resumed print needs one)."""
        from cdprhost.link import LinkError

        link = self.link
        try:
            link.request_status(timeout=self.profile.serial.timeout_s)
        except (LinkError, OSError):
            if self._where is None:
                raise
            self.connect(*self._where)
            link = self.link
        return link

    # ----------------------------------------------------------------- jog
    @property
    def machine(self) -> Machine:
        return Machine(self.link, self.profile, self.model, feed_mm_s=JOG_SPEED_MM_S)

    def move_to(
        self, target: tuple[float, float, float], speed_mm_s: float = JOG_SPEED_MM_S
    ) -> DeviceStatusView:
        """Plan and execute a straight move to ``target`` (machine frame); requires homing."""
        try:
            return self._status_view(self.machine.move_to(target, feed_mm_s=speed_mm_s))
        except NotHomed:
            raise CdprError("the modules are not homed: home first") from None

    def jog_to(self, target: tuple[float, float, float]) -> DeviceStatusView:
        return self.move_to(target)

    def home(self) -> DeviceStatusView:
        return self._status_view(self.machine.home())

    def motors_off(self) -> DeviceStatusView:
        return self._status_view(self.machine.motors_off())

    def set_heaters(self, hotend_c: float, bed_c: float) -> DeviceStatusView:
        return self._status_view(self.machine.set_heaters(hotend_c, bed_c))

    def emergency_stop(self) -> bool:
        return bool(self.machine.emergency_stop())

    def console(self, line: str) -> list[ConsoleLine]:
        from cdprhost.tui.control.live_console import run_console

        try:
            machine = self.machine
        except CdprError as exc:
            return [ConsoleLine("sent", line, time.time()), ConsoleLine("error", str(exc))]
        from cdprhost.link import LinkError

        out = run_console(line, machine, self._status_view, self._identity, JOG_SPEED_MM_S)
        try:
            self._note_events(machine.link.poll(0.0, fault_ok=True))
        except (LinkError, OSError) as exc:  # stopped (M112) or lost: said, not raised
            out.append(ConsoleLine("device", str(exc) or "the link failed", time.time()))
        return out + self.device_log()

    # ---------------------------------------------------------- calibrate
    def wizard_device(self, settle_s: float) -> Machine:
        """The wizard's device (:class:`~cdprhost.tui.control.live_calibration.WizardHost`)."""
        return Machine(self.link, self.profile, self.model, settle_s=settle_s)

    def virtual_mocap(self) -> str | None:
        """The virtual motion capture's folder (it watches from the connection on)."""
        folder = getattr(self.sim_options.get("observer"), "directory", None)
        return None if folder is None else str(folder)

    def simulated_camera(self, size: tuple[int, int]) -> Any:
        """The simulated camera watching a new embedded simulated device."""
        from cdprhost.errors import InputError
        from cdprhost.sim.camera.device import VirtualCamera
        from cdprhost.sim.camera.scene import rig_for_size

        if getattr(self._link, "device", None) is None:
            raise InputError(
                "camera sim watches the embedded simulated device: connect to it first"
            )
        camera = VirtualCamera(self.model, rig_for_size(size))
        self.sim_options["observer"] = camera
        self.connect(EMBEDDED, self.profile.serial.baud)
        return camera

    # ------------------------------------------------------------ diagnose
    def diagnose(self, session_dir: str) -> DiagnosisView:
        from cdprhost.tui.control.live_diagnosis import run_diagnosis_kept

        view, result = run_diagnosis_kept(session_dir, self.model, self.diagnosis_settings)
        self.diagnosed.keep(session_dir, result)
        return view

    def diagnosed_write_plan(self) -> Any:
        """Where the last diagnosis' improved profile would be written (a ``WritePlan``)."""
        return self.diagnosed.plan(self.profile_ref)

    def write_diagnosed_profile(self) -> str:
        """Blocking: write the last diagnosis' improved profile; the path written."""
        return self.diagnosed.write(self.profile, self.profile_ref)

    def close(self) -> None:
        self.disconnect()
