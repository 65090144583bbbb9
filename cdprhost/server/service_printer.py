"""The printer of ``cdprhost serve``: a client of the printer service (:mod:`cdprhost.service`).

Every job runs in the service's process, on the device the service owns; this server only
sends commands and folds the service's event stream into the :class:`PrinterStatus` the API,
the web page and its event stream report. So a server that hangs, crashes or is killed never
touches a print, and a server started again attaches to the running service and shows the
print it finds there (its file and who started it come with the replay). The server holds
the service's device session (:mod:`cdprhost.service.device_session`), the one the terminal
UI holds too: the page's device commands are the session's operations (``estop``,
``heaters`` off, ``home``, a jog as a checked ``move``), its temperatures between prints the
session's ``device`` broadcasts; pause, resume and cancel are the job's.

A service is found or started for the device by the rule every front end follows
(:func:`cdprhost.service.client.attach`): ``--port``'s shared service, or for the embedded
simulated device one service per state folder (so a restarted ``serve`` or a ``tui``
finds it again). ``cdprhost tui --listen`` serves its page with this printer on the TUI's
own service: the TUI and the page are two clients of one service.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.job.resume import log_path_for
from cdprhost.job.state import (
    Event,
    IllegalTransition,
    JobSnapshot,
    JobState,
    Temperatures,
    reduce,
)
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.prepared import Setup
from cdprhost.profile.models import MachineProfile
from cdprhost.server.printer import (
    PrinterStatus,
    Refused,
    refuse_if_busy,
    refuse_if_faulted,
    refuse_unless_preflight_passes,
)
from cdprhost.server.web_controls import JOG_FEED_MM_S, jog_target
from cdprhost.service import wire
from cdprhost.service.client import ServiceClient, ServiceError, attach
from cdprhost.service.paths import ServiceFiles, files_for_port

log = logging.getLogger(__name__)

WHO = "serve"
REPLY_TIMEOUT_S = 30.0  # a start's reply, a pause's; a device command's below
DEVICE_TIMEOUT_S = 120.0  # homing a machine takes its time
TEMPERATURE_MAX_AGE_S = 2.0  # an idle reading younger than this answers (the session's
# broadcast comes about once a second)
RECONNECT_S = 1.0


class _Waiter:
    def __init__(self) -> None:
        self.done = threading.Event()
        self.reply: Any = None


class ServicePrinter:
    def __init__(
        self,
        profile: MachineProfile,
        *,
        port: str | None = None,
        baud: int | None = None,
        speedup: float | None = None,
        setup: Setup | None = None,
        clear_fault: bool = False,
        profile_ref: str | None = None,
        on_event: Callable[[Event], None] | None = None,
        files: ServiceFiles | None = None,
    ):
        """``clear_fault``: a start clears a device fault (someone checked the machine); by
        default a faulted device refuses the start (the job says why)."""
        self.profile = profile
        self.model = MachineModel.from_profile(profile)
        self.setup = setup or Setup()
        self.port = port
        self.baud = baud
        self.speedup = speedup
        self.clear_fault = clear_fault
        self.profile_ref = profile_ref
        self.job_options: dict[str, Any] = {}
        self.files = files or files_for_port(port)
        self._listeners = [on_event] if on_event else []
        self._lock = threading.RLock()
        self._status = PrinterStatus(connected=False)
        self._client: ServiceClient | None = None
        self._waiting: dict[int, _Waiter] = {}
        self._ended = threading.Event()
        self._ended.set()
        self._closing = False
        self._idle_temps: tuple[float, Temperatures] | None = None
        self._mine: float | None = None  # the start time of the job this server started
        self._profile_json = profile.model_dump(mode="json")
        self._device: tuple[float, wire.DeviceState] | None = None  # (monotonic, newest)

    # ------------------------------------------------------------ the service
    def connect(self) -> None:
        """Find or start the service and hold its device session (a wrong port is said
        before anything listens): CdprError (ServiceError, or the device's own) when it
        fails."""
        self._attach()
        threading.Thread(target=self._keep_attached, name="service-watch", daemon=True).start()

    def _attach(self) -> None:
        """Attach, hold the device session, then show the service as connected (nothing is
        asked of a service before it holds the device for us)."""
        client = attach(self.port, WHO, replay=True, files=self.files)
        threading.Thread(target=self._read, args=(client,), name="service-in", daemon=True).start()
        connect = wire.Connect(
            profile=self._profile_json,
            baud=self.baud if self.port else None,
            speedup=None if self.port else self.speedup,
        )
        try:
            answer = self._ask(connect, DEVICE_TIMEOUT_S, client=client)
        except Refused as exc:
            client.close()
            raise CdprError(str(exc)) from None
        if not answer.ok:
            client.close()
            raise CdprError(f"the device does not answer: {answer.error}")
        self._seen(answer.status)
        fresh = client.welcome is None or client.welcome.job == "none"
        with self._lock:
            self._client = client
            if fresh and self._status.busy:  # a new service: the job we showed died with the old
                reason = "the printer service went away during the print"
                log.warning("%s (started again)", reason)
                job = replace(self._status.job, state=JobState.FAILED, reason=reason)
                self._status = replace(self._status, job=job, ended_at=time.time())
                self._ended.set()
            self._status = replace(self._status, connected=True)
        if client.welcome is not None and client.welcome.job != "none":
            log.info("attached to the printer service: its job is %s", client.welcome.job)

    def _keep_attached(self) -> None:
        """A service that went away (it never does while a client is attached, short of a
        crash) is looked for again, and started again when the server still runs."""
        while not self._closing:
            time.sleep(RECONNECT_S)
            if self._client is not None or self._closing:
                continue
            try:
                self._attach()
            except (ServiceError, CdprError, OSError) as exc:
                log.warning("the printer service cannot be reached: %s", exc)

    def _read(self, client: ServiceClient) -> None:
        while True:
            message = client.inbox.get()
            if message is None:
                break
            self._take(message)
        with self._lock:
            current = self._client is client
            if current:
                self._client = None
                self._status = replace(self._status, connected=False)
            waiting, self._waiting = self._waiting, {}
        for waiter in waiting.values():
            waiter.done.set()  # no reply: the caller says the service went away
        if not self._closing:
            log.warning("the printer service went away: %s", client.gone or "no reason")

    def _take(self, message: Any) -> None:
        if isinstance(message, wire.EventMsg):
            try:
                self._on_event(wire.event_from_json(message.event))
            except wire.WireError as exc:
                log.warning("the printer service sent a bad event: %s", exc)
        elif isinstance(message, wire.JobInfo):
            with self._lock:  # a new job (or the one that runs, for a server attaching late)
                self._status = PrinterStatus(
                    connected=True,
                    file=Path(message.gcode) if message.gcode else None,
                    started_by=message.started_by,
                    job=JobSnapshot(),
                    started_at=message.started_at,
                )
                self._ended.clear()
        elif isinstance(message, wire.ResultMsg):
            with self._lock:
                if not self._status.job.state.finished and message.error:
                    log.warning("the print job broke in the service: %s", message.error)
                self._ended.set()
        elif isinstance(message, wire.DeviceMsg):
            self._seen(message.status)
        elif isinstance(message, (wire.Reply, wire.Answer)):
            with self._lock:
                waiter = self._waiting.pop(message.id, None)
            if waiter is not None:
                waiter.reply = message
                waiter.done.set()
        elif isinstance(message, wire.LogMsg):
            log.info("printer service: %s %s", message.level, message.text)

    def _on_event(self, event: Event) -> None:
        with self._lock:
            try:
                job = reduce(self._status.job, event)
            except IllegalTransition as exc:
                log.warning("job event out of order: %s", exc)
                return
            ended = job.state.finished and not self._status.job.state.finished
            self._status = replace(
                self._status, job=job, ended_at=time.time() if ended else self._status.ended_at
            )
        for listener in self._listeners:
            listener(event)

    def _ask(
        self, message: Any, timeout_s: float = REPLY_TIMEOUT_S, client: ServiceClient | None = None
    ) -> Any:
        """Send a command and wait for its reply; Refused when the service is gone."""
        with self._lock:
            client = client or self._client
            if client is None:
                raise Refused("the printer service cannot be reached; nothing done")
            waiter = _Waiter()
            try:
                number = client.send(message)  # the reply cannot come before we listen
            except ServiceError as exc:
                raise Refused(f"{exc}; nothing done") from None
            self._waiting[number] = waiter
        if not waiter.done.wait(timeout_s) or waiter.reply is None:
            with self._lock:
                self._waiting.pop(number, None)
            raise Refused("the printer service did not answer; nothing done")
        return waiter.reply

    def _operate(self, request: Any) -> wire.DeviceState | None:
        """A device-session operation: the device's status after it, or Refused."""
        answer = self._ask(request, DEVICE_TIMEOUT_S)
        if not answer.ok:
            raise Refused(answer.error)
        self._seen(answer.status)
        return answer.status  # type: ignore[no-any-return]

    def _seen(self, state: wire.DeviceState | None) -> None:
        if state is not None:
            self._device = (time.monotonic(), state)

    # ------------------------------------------------------------ Printer
    def status(self) -> PrinterStatus:
        return self._status

    def check_start(self, path: Path) -> None:
        self._refuse_if_busy()
        refuse_unless_preflight_passes(path, self.profile, self.model, self.setup)
        self._refuse_if_faulted()

    def _refuse_if_faulted(self) -> None:
        self._refuse_if_busy()
        try:
            state = self._operate(wire.Status())
        except Refused as exc:
            raise Refused(f"the device does not answer: {exc}; nothing started") from None
        if state is not None:
            refuse_if_faulted(state.fault, state.clearable, self.clear_fault)

    def _refuse_if_busy(self) -> None:
        refuse_if_busy(self._status, self._closing)

    def start(self, path: Path, who: str) -> None:
        self._refuse_if_busy()
        log_path = log_path_for(path)
        with contextlib.suppress(OSError):
            log_path.parent.mkdir(parents=True, exist_ok=True)
        spec = wire.StartJob(
            gcode=str(path.resolve()),
            profile=self._profile_json,
            port=self.port,
            baud=self.baud,
            speedup=self.speedup,
            setup=self.setup.to_json(),
            log_path=str(log_path.absolute()),
            profile_ref=self.profile_ref if self.port else None,
            started_by=who[:200],
            clear_fault=self.clear_fault,
        )
        reply = self._ask(wire.Start(job=spec))
        if not reply.ok:
            raise Refused(f"{reply.error}; nothing started")
        self._mine = self._status.started_at  # its JobInfo came before the reply
        log.info("print of %s started by %s", path.name, who)

    def pause(self, action: str) -> None:
        state = self._status.job.state
        if not self._status.busy:
            raise Refused(f"no print is running ({state.value}): nothing to {action}")
        if action == "toggle":
            action = "resume" if state is JobState.PAUSED else "pause"
        if action == "pause":
            if state not in (JobState.PRINTING, JobState.HEATING):
                raise Refused(f"cannot pause while {state.value}")
            self._command(wire.Pause())
        elif action == "resume":
            if state is not JobState.PAUSED:
                raise Refused(f"cannot resume while {state.value}")
            self._command(wire.Resume())
        else:
            raise ValueError(f"unknown pause action {action!r}")

    def cancel(self, reason: str = "") -> None:
        """Also while the job starts (preflight, connecting): it then ends before moving."""
        status = self._status
        if not status.busy:
            raise Refused(f"no print is running ({status.job.state.value}): nothing to cancel")
        if status.job.state is JobState.CANCELLING:
            return
        self._command(wire.Cancel(reason=reason))

    def _command(self, message: Any) -> None:
        reply = self._ask(message)
        if not reply.ok:
            raise Refused(reply.error)

    def emergency_stop(self) -> bool:
        """Stop now: the job's e-stop when one runs, else the device session's (motors
        kept)."""
        try:
            answer = self._ask(wire.Estop(), 5.0)
        except Refused as exc:
            log.warning("emergency stop: %s", exc)
            return False
        if not answer.ok:
            log.warning("emergency stop: %s", answer.error)
            return False
        return bool(getattr(answer, "confirmed", True))

    def device(self, action: str, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> str:
        """Blocking: a device command of the web page (e-stop, heaters off, home, jog) done
        by the service's device session; what was done, or Refused with the reason."""
        if action == "estop":
            if not self.emergency_stop():
                raise Refused("the device did not acknowledge the e-stop")
            return "emergency stop (motors kept)"
        if self._status.busy:
            what = action.replace("_", " ")
            raise Refused(f"a print is running: {what} refused; nothing done")
        if action == "heaters_off":
            self._operate(wire.Heaters(hotend=0.0, bed=0.0))
            return "heaters off"
        if action == "home":
            self._operate(wire.Home())
            return "homed"
        if action != "jog":
            raise Refused(f"{action}: not a device command")
        delta = (dx, dy, dz)
        if not any(delta):
            raise Refused("a jog of 0 mm: nothing to do")
        state = self._operate(wire.Status())
        if state is None or state.homed_mask & 0b111 != 0b111:
            raise Refused("home first: the machine does not know where it is; nothing moved")
        model = self.model
        here = model.fk(model.sliders_from_steps(np.asarray(state.steps[:3]))[None, :])[0]
        self._operate(wire.MoveTo(target=jog_target(model, here, delta), feed_mm_s=JOG_FEED_MM_S))
        return "jogged"

    def uploaded(self, path: Path) -> None:
        log.info("stored upload %s", path)

    def temperatures(self) -> Temperatures | None:
        """The running job's newest reading; without a job, the device session's (its
        broadcast, or asked when that is older than ``TEMPERATURE_MAX_AGE_S``)."""
        status = self._status
        if status.busy:
            return status.job.temperatures
        seen = self._device
        if seen is None or time.monotonic() - seen[0] >= TEMPERATURE_MAX_AGE_S:
            with contextlib.suppress(Refused):
                self._operate(wire.Status())
            seen = self._device
        if seen is None:
            return status.job.temperatures
        st = seen[1]
        age = time.monotonic() - seen[0]
        return Temperatures(st.hotend_c, st.bed_c, st.hotend_target_c, st.bed_target_c, age)

    def device_state(self) -> wire.DeviceState | None:
        """The device's newest status from the service (None: none seen yet)."""
        seen = self._device
        return seen[1] if seen is not None else None

    # ------------------------------------------------------------ the end
    def wait_idle(self, timeout_s: float) -> bool:
        """Blocking: until no job runs (for tests and the CLI)."""
        end = time.monotonic() + timeout_s
        while self._status.busy and time.monotonic() < end:
            time.sleep(0.05)
        return not self._status.busy

    def shutdown(self, reason: str = "server shutdown", timeout_s: float = 30.0) -> bool:
        """Blocking: refuse new starts, cancel a running print this server started (the
        service stops it safely: stop, park, heaters off, resume point) and wait for its
        end, then leave the service. A print started by another front end (or by a server
        before this one) goes on. True when no job of this server was left running."""
        self._closing = True
        ended = True
        status = self._status
        if status.busy and (self._mine is None or status.started_at != self._mine):
            name = status.file.name if status.file else "the print"
            log.warning("%s goes on in the printer service (not started here)", name)
        elif status.busy:
            log.warning("stopping the running print (%s)", reason)
            with contextlib.suppress(Refused):
                self._command(wire.Cancel(reason=reason))
            ended = self.wait_idle(timeout_s)
            if not ended:
                ended = self.emergency_stop() and self.wait_idle(10.0)
        self.detach()
        return ended

    def detach(self) -> None:
        """Leave the service (a print goes on)."""
        self._closing = True
        with self._lock:
            client, self._client = self._client, None
        if client is not None:
            client.close()
