"""The printer service's device session: the one link to its device while a front end
holds it or a job needs it, the machine operations between prints, and the device's status
broadcast to every client.

A front end ``connect``s (the service opens the link, or shares the one it has) and
``disconnect``s or leaves (the link closes once nobody holds it and no job runs); a
client that connects during a print started without a session shares the print's link. While
it is open a poll thread reads the device about once a second (pumping the embedded
device's virtual clock between reads) and hands the status and the link's counters to
``broadcast``. Operations (home, a move, heaters, drivers, clearing a fault, and the
calibration wizard's visits and simulated observers) run one at a time under one lock; the poll then only asks for a status and reads the latest, so
temperatures keep coming during a long homing. A job takes the same link
(:meth:`DeviceSession.link_for_job`) and its own events carry the device's state; the poll
waits meanwhile. An emergency stop never waits for the lock.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from cdprhost.errors import CdprError
from cdprhost.service import wire

log = logging.getLogger(__name__)

POLL_S = 1.0
#: the embedded device's clock runs while its link is pumped: this share of each poll
PUMP_SHARE = 0.8
BUSY_STATUS_MAX_AGE_S = 2.0
HEAT_WAIT_S = 900.0
#: the embedded simulated device keeps this many executed segments (memory stays flat)
RECORD_KEEP = 4096
IDENTITY_FIELDS = (
    "protocol",
    "firmware_name",
    "firmware_version",
    "axes",
    "queue_capacity",
    "clock_hz",
    "max_step_rate",
    "heaters",
    "fans",
    "boot_id",
)

Opener = Callable[[wire.Connect, Any], Any]


def default_opener(port: str | None) -> Opener:
    """How the session opens its link: the service's port, or a new embedded device."""

    def open_(spec: wire.Connect, profile: Any) -> Any:
        if port is not None:
            from cdprhost.link import open_link

            return open_link(port, spec.baud or profile.serial.baud, profile.serial.timeout_s)
        from cdprhost.sim.embedded import open_embedded

        return open_embedded(
            speedup=spec.speedup, timeout_s=profile.serial.timeout_s, record_keep=RECORD_KEEP
        )

    return open_


def device_state(st: Any) -> wire.DeviceState:
    """A link's status report for the wire."""
    from cdprhost.machine.prepare import describe_fault, fault_clearable

    return wire.DeviceState(
        steps=tuple(int(v) for v in st.steps),  # type: ignore[arg-type]
        hotend_c=float(st.hotend_c),
        bed_c=float(st.bed_c),
        hotend_target_c=float(st.hotend_target_c),
        bed_target_c=float(st.bed_target_c),
        enabled_mask=int(st.enabled_mask),
        homed_mask=int(st.homed_mask),
        queue_free=int(st.queue_free),
        fault=describe_fault(st) or "",
        clearable=fault_clearable(st),
    )


def read_state(link: Any) -> wire.DeviceState:
    """The device's status now; a device stopped by a fault (the link raises it) still
    answers, with the fault in words and its last report's figures."""
    from cdprhost.link.errors import DeviceFault
    from firmware_protocol.messages import THERMAL_ERRORS

    try:
        return device_state(link.request_status())
    except DeviceFault as exc:
        st = link.status()
        if st is None:
            raise
        state = device_state(st)
        if state.fault:
            return state
        fault = f"the device is stopped by a fault ({exc})"
        clearable = int(exc.code or 0) not in THERMAL_ERRORS
        return state.model_copy(update={"fault": fault, "clearable": clearable})


def move_refusal(model: Any, st: Any, target: tuple[float, float, float]) -> str:
    """Why the straight move from where the device is to ``target`` leaves the workspace
    ("" when it does not; the path is sampled every millimetre)."""
    if st.homed_mask & 0b111 != 0b111:
        return ""  # the move itself refuses: not homed
    return path_refusal(model, st, [target])


def path_refusal(model: Any, st: Any, targets: Any, home: Any = None) -> str:
    """Why the straight moves from where the device is (when homed and known; else from
    ``home``, where homing leaves it, when given) through ``targets`` in order leave the
    workspace ("" when they do not; sampled every mm)."""
    ends = np.asarray(targets, dtype=float).reshape(-1, 3)
    legs = [ends[:1]]
    start = ends[0] if home is None else np.asarray(home, dtype=float).reshape(3)
    if st.homed_mask & 0b111 == 0b111:
        here = model.fk(model.sliders_from_steps(np.asarray(st.steps[:3]))[None, :])[0]
        if np.all(np.isfinite(here)):
            start = here
    for end in ends:
        n = max(2, int(np.ceil(np.linalg.norm(end - start))) + 1)
        legs.append(start + np.linspace(0.0, 1.0, n)[:, None] * (end - start))
        start = end
    points = np.concatenate(legs)
    report = model.check(points)
    if report.ok.all():
        return ""
    i = int(np.argmin(report.ok))
    return f"{report.rule_name(i)}: {report.describe(i, model.limits)}"


def identity_json(identity: Any, caps: Any = None) -> dict[str, Any]:
    """The device's identity for the wire, with its CAPS' shortest segment and the step
    budget its axes share (STEP_BUDGET) when announced."""
    out = {name: getattr(identity, name, None) for name in IDENTITY_FIELDS}
    out["protocol"] = list(out["protocol"] or ())
    if caps is not None:
        out["min_segment_ticks"] = int(caps.min_segment_ticks)
        if caps.total_step_rate is not None:
            out["total_step_rate"] = int(caps.total_step_rate)
    return out


class DeviceSession:
    """``job_active()``: whether a job holds the link now (the session then stays out)."""

    def __init__(
        self,
        port: str | None,
        broadcast: Callable[[BaseModel], None],
        job_active: Callable[[], bool],
        opener: Opener | None = None,
        poll_s: float = POLL_S,
        job_link: Callable[[], Any] | None = None,
    ):
        self.port = port
        self.broadcast = broadcast
        self.job_active = job_active
        self.job_link = job_link or (lambda: None)
        self.opener = opener or default_opener(port)
        self.poll_s = poll_s
        self._lock = threading.RLock()  # the session's fields
        self._op = threading.Lock()  # one operation on the device at a time
        self._link: Any = None
        self._spec: wire.Connect | None = None
        self._profile: Any = None
        self._model: Any = None
        self._holders: set[int] = set()
        self._stop = threading.Event()
        self._poller: threading.Thread | None = None
        self._last: wire.DeviceState | None = None
        self._camera: Any = None  # the simulated camera on the embedded device (observe)

    # ------------------------------------------------------------ holding
    @property
    def open(self) -> bool:
        return self._link is not None

    def holds(self, link: Any) -> bool:
        return link is not None and link is self._link

    def connect(self, holder: int, spec: wire.Connect) -> wire.Answer:
        """Hold the device for ``holder``; open its link when none is open."""
        from cdprhost.kinematics import MachineModel
        from cdprhost.profile.models import MachineProfile

        try:
            profile = MachineProfile.model_validate(spec.profile)
        except ValidationError as exc:
            return wire.Answer(id=spec.id, ok=False, error=f"refused: connect: {exc}")
        with self._lock:
            if self._link is None:
                # a print started without a session (``cdprhost print``) has the device open:
                # the session takes that link over (kept after the print for the holders)
                link = self.job_link() if self.job_active() else None
                try:
                    link = link if link is not None else self.opener(spec, profile)
                except (CdprError, OSError) as exc:
                    return wire.Answer(id=spec.id, ok=False, error=str(exc) or type(exc).__name__)
                self._link, self._spec, self._profile = link, spec, profile
                self._model = MachineModel.from_profile(profile)
                self._start_poll()
                log.info("device session opened (%s)", self.port or "embedded device")
            self._holders.add(holder)
            link = self._link
        status = self._last if self.job_active() else self._status_now()
        return wire.Answer(
            id=spec.id,
            ok=True,
            identity=identity_json(link.identity, getattr(link, "caps", None)),
            status=status,
        )

    def release(self, holder: int, job_ended: bool = False, closing: bool = False) -> None:
        """``holder`` lets go (disconnected or left); a port's link closes when nobody holds
        it and no job runs (``job_ended``: the job's own thread says it is over). The
        embedded simulated device lives in the link, so its link stays open until the
        service closes (``closing``): a front end started again finds the machine as it
        was (homed, hot)."""
        with self._lock:
            self._holders.discard(holder)
            if self._holders or (self.job_active() and not job_ended):
                return
            if self.port is None and not closing:
                return
            link, self._link = self._link, None
            self._stop.set()
        if link is not None:
            log.info("device session closed")
            with contextlib.suppress(Exception):
                link.close()

    def after_job(self) -> None:
        """A job ended: keep the link for the holders, or close it."""
        with self._lock:
            nobody = not self._holders
        if nobody:
            self.release(-1, job_ended=True)

    def close(self) -> None:
        with self._lock:
            self._holders.clear()
        self.release(-1, closing=True)

    # ------------------------------------------------------------ the job
    def link_for_job(self) -> Any:
        """The session's link for a job; opened again first when it failed (a device reset
        leaves it failed until a new session, and a resumed print needs one)."""
        from cdprhost.link import LinkError

        with self._op:
            link = self._link
            if link is None:
                raise CdprError("the device session is closed")
            try:
                link.request_status(timeout=self._profile.serial.timeout_s)
            except (LinkError, OSError):
                link = self._reopen()
            return link

    def _reopen(self) -> Any:
        with self._lock:
            old, spec, profile = self._link, self._spec, self._profile
        assert spec is not None
        with contextlib.suppress(Exception):
            old.close()
        link = self.opener(spec, profile)
        with self._lock:
            self._link = link
        self.broadcast(wire.Note(kind="notice", text="the link to the device was opened again"))
        return link

    # ------------------------------------------------------------ operations
    def run(self, request: Any) -> wire.Answer:
        """Carry out one operation (blocking); the answer with the device's status after."""
        from cdprhost.link import LinkError
        from cdprhost.machine import NotHomed

        if self._link is None:
            return wire.Answer(id=request.id, ok=False, error="not connected: connect first")
        if self.job_active():
            if isinstance(request, wire.Status):
                return wire.Answer(id=request.id, ok=True, status=self._last)
            return wire.Answer(
                id=request.id,
                ok=False,
                error="a print is running: pause or cancel it first; nothing was sent",
            )
        try:
            with self._op:
                if self._link is None:  # closed meanwhile
                    raise CdprError("not connected: connect first")
                status = self._carry_out(request)
        except NotHomed:
            return wire.Answer(
                id=request.id, ok=False, error="the modules are not homed: home (G28) first"
            )
        except (CdprError, LinkError, OSError) as exc:
            return wire.Answer(id=request.id, ok=False, error=str(exc) or type(exc).__name__)
        self._note(self._link)
        status, extra = status if isinstance(status, tuple) else (status, {})
        state = status if isinstance(status, wire.DeviceState) else device_state(status)
        self._last = state
        if not isinstance(request, wire.Status):  # every client sees what one of them did
            self.broadcast(wire.DeviceMsg(connected=True, status=state))
        return wire.Answer(id=request.id, ok=True, status=state, **extra)

    def _carry_out(self, request: Any) -> Any:
        from cdprhost.machine import Machine

        if isinstance(request, wire.Status):  # (the poll thread pumps the embedded clock)
            self._note(self._link)
            return read_state(self._link)
        if isinstance(request, wire.ClearFault):
            self._link.clear_fault()
            return self._link.request_status()
        m = Machine(self._link, self._profile, self._model)
        if isinstance(request, wire.Home):
            return m.home()
        if isinstance(request, wire.MoveTo):
            refused = move_refusal(self._model, m.status(), request.target)
            if refused:
                raise CdprError(f"refused, nothing moved: {refused}")
            return m.move_to(request.target, feed_mm_s=request.feed_mm_s)
        if isinstance(request, wire.Heaters):
            heaters = self._profile.heaters
            for name, value, top in (
                ("hotend", request.hotend, heaters.hotend_max_c),
                ("bed", request.bed, heaters.bed_max_c),
            ):
                if value is not None and value > top:
                    raise CdprError(f"refused: {name} target {value:g} °C is above {top:g} °C")
            st = m.set_heaters(request.hotend, request.bed, wait=request.wait)
            if request.wait:
                self._link.wait_idle(HEAT_WAIT_S)
                st = m.status()
            return st
        if isinstance(request, wire.MotorsOff):
            return m.motors_off()
        if isinstance(request, wire.Enable):
            return m.enable()
        if isinstance(request, wire.Visit | wire.Observe | wire.Capture):
            return self._calibration(request)
        raise CdprError(f"{request.op}: not a device operation")

    def _calibration(self, request: Any) -> tuple[Any, dict[str, Any]]:
        """The calibration wizard's requests: a visit (refused on a faulted device, or
        leaving the workspace, before anything moves), the embedded device's observer, the
        simulated camera's pictures. The status after, and the answer's own fields."""
        from cdprhost.machine import Machine
        from cdprhost.service import sim_world

        if isinstance(request, wire.Visit):
            m = Machine(self._link, self._profile, self._model, settle_s=request.settle_s)
            home = self._model.home_point(np.asarray(self._profile.drive.home_mm))
            refused = path_refusal(self._model, m.ready(), request.points, home)
            if refused:
                raise CdprError(f"refused, nothing moved: {refused}")
            _steps, device_time_s = m.visit(np.asarray(request.points, dtype=float))
            return m.status(), {"device_time_s": device_time_s}
        device = getattr(self._link, "device", None)
        if isinstance(request, wire.Observe):
            if self.port is not None or device is None:
                raise CdprError(f"refused: {sim_world.NOT_EMBEDDED}")
            observer = sim_world.make_observer(request, self._model)
            sim_world.watch(device, observer)
            self._camera = observer if request.camera is not None else None
            return read_state(self._link), {}
        camera = self._camera
        if camera is None:
            raise CdprError("no simulated camera watches the device: observe with a camera first")
        return read_state(self._link), {
            "files": sim_world.capture(camera, request.folder, request.frames)
        }

    def emergency_stop(self, request_id: int) -> wire.Answer:
        """Stop now, not waiting for a running operation (the link is thread-safe)."""
        from cdprhost.machine import Machine

        link = self._link
        if link is None:
            return wire.Answer(id=request_id, ok=False, error="not connected: connect first")
        try:
            confirmed = bool(Machine(link, self._profile, self._model).emergency_stop())
        except (CdprError, OSError) as exc:
            return wire.Answer(id=request_id, ok=False, error=str(exc) or type(exc).__name__)
        return wire.Answer(id=request_id, ok=True, confirmed=confirmed)

    # ------------------------------------------------------------ the poll
    def _pump(self) -> float:
        spec = self._spec
        if self.port is not None or spec is None:
            return 0.0
        return PUMP_SHARE * self.poll_s * (spec.speedup or 1.0)

    def _note(self, link: Any, pump: float = 0.0) -> None:
        from cdprhost.link import DeviceErrorEvent, DeviceEvent
        from cdprhost.link.errors import DeviceFault

        try:
            events = link.poll(pump)
        except DeviceFault:  # stopped by a fault: the status says it (read_state)
            return
        for ev in events:
            if isinstance(ev, DeviceErrorEvent):
                text = f"device error {ev.name}" + (f": {ev.text}" if ev.text else "")
                self.broadcast(wire.Note(kind="error", text=text))
            elif isinstance(ev, DeviceEvent):
                values = " ".join(str(v) for v in ev.values)
                self.broadcast(wire.Note(kind="device", text=f"{ev.name} {values}".strip()))

    def _status_now(self) -> wire.DeviceState | None:
        with contextlib.suppress(Exception), self._op:
            self._last = read_state(self._link)
        return self._last

    def _start_poll(self) -> None:
        self._stop = threading.Event()
        thread = threading.Thread(
            target=self._poll_loop, args=(self._stop,), name="device-poll", daemon=True
        )
        self._poller = thread
        thread.start()

    def _poll_loop(self, stop: threading.Event) -> None:
        while not stop.wait(0.0 if self._pump() else self.poll_s):
            link = self._link
            if link is None:
                break
            if self.job_active():
                stop.wait(self.poll_s)
                continue
            self.broadcast(self._read(link))

    def _read(self, link: Any) -> wire.DeviceMsg:
        health = None
        with contextlib.suppress(Exception):
            c = link.counters
            health = wire.Health(
                retransmits=c.retransmits, bad_frames=c.bad_frames, naks=c.naks_received
            )
        try:
            if self._op.acquire(blocking=False):
                try:
                    self._note(link, pump=self._pump())
                    self._last = read_state(link)
                finally:
                    self._op.release()
                return wire.DeviceMsg(connected=True, status=self._last, health=health)
            else:  # an operation holds the device: ask, and read the latest if recent
                time.sleep(self.poll_s)
                link.ask_status()
                st = link.status()
                if st is None or link.now() - st.received_at > BUSY_STATUS_MAX_AGE_S:
                    return wire.DeviceMsg(connected=True, status=None, health=health)
        except Exception as exc:  # noqa: BLE001 - said to every client, the poll goes on
            return wire.DeviceMsg(connected=True, health=health, error=str(exc) or repr(exc))
        self._last = device_state(st)
        return wire.DeviceMsg(connected=True, status=self._last, health=health)
