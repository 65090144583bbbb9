"""The UI backend as a client of the printer service (:mod:`cdprhost.service`): the print,
the link, the console, jogging and the heaters live in the service's process; this process
only draws. A TUI that hangs, is stopped or is killed never touches a print, and a TUI
started while a print runs shows it (the service replays its events).

``connect`` attaches to the service of the chosen port (starting it when none runs; the
embedded simulated device has one service per state folder) and holds its device session. One
reader thread sorts what the service sends: the running job's events to its sink, answers
to the request that waits for them, the device's status and notes to the screens. Files
(preflight, resume points, centring) and diagnosis are computed here, as before, by a
:class:`~cdprhost.tui.control.live.LiveBackend` that never opens a link; so is the
calibration wizard, whose moves and simulated observers the service carries out
(:mod:`~cdprhost.tui.control.service_calibration`).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

from cdprhost.errors import CdprError
from cdprhost.job.state import Event, LinkHealth
from cdprhost.machine import NotHomed
from cdprhost.profile import MachineProfile
from cdprhost.service import client as service_client
from cdprhost.service import wire
from cdprhost.tui.control.backend import EMBEDDED, CalibrationBackend, EventSink
from cdprhost.tui.control.live import (
    DEVICE_LOG,
    JOG_SPEED_MM_S,
    LiveBackend,
    device_status_view,
    identity_rows,
)
from cdprhost.tui.control.service_proxies import RemoteMachine, ServiceJob
from cdprhost.tui.control.views import (
    ConsoleLine,
    DeviceStatusView,
    DiagnosisView,
    PortChoice,
    PreflightView,
    ResumeView,
)

FRESH_S = 2.0  # a broadcast status younger than this answers ``device_status``
STATUS_TIMEOUT_S = 15.0


def status_view(model: Any, st: wire.DeviceState) -> DeviceStatusView:
    """The service's status of the device as the screens show it (position by the model)."""
    return device_status_view(model, st, st.fault, st.clearable)


class ServiceBackend:
    """``attach``: how to reach a service (:func:`cdprhost.service.client.attach`; tests
    give their own). ``sim_mocap``: (truth profile, folder) of the virtual motion capture
    that watches the embedded simulated device for the calibration wizard."""

    print_outlives_ui = True  # the print runs in the service: quitting the UI leaves it going

    def __init__(
        self,
        profile: str | MachineProfile,
        *,
        speedup: float | None = 10.0,
        diagnosis_settings: Any = None,
        setup: Any = None,
        attach: Any = None,
        sim_mocap: tuple[str, str] | None = None,
    ):
        from cdprhost.tui.control.live_calibration import LiveCalibration

        self.local = LiveBackend(
            profile, speedup=speedup, diagnosis_settings=diagnosis_settings, setup=setup
        )
        self.local.calibration = None
        self.profile = self.local.profile
        self.profile_name = self.local.profile_name
        self.model = self.local.model
        self.speedup = speedup
        self.attach = attach or service_client.attach
        self._client: service_client.ServiceClient | None = None
        self._where: tuple[str, int] = (EMBEDDED, 0)
        self._cond = threading.Condition()
        self._answers: dict[int, Any] = {}
        self._job: ServiceJob | None = None
        self._replayed: list[Event] = []  # a running job's events, before the UI adopts it
        self._job_info: wire.JobInfo | None = None
        self._device: tuple[float, wire.DeviceMsg] | None = None
        self._log: deque[ConsoleLine] = deque(maxlen=DEVICE_LOG)
        self._identity: tuple[tuple[str, str], ...] = ()
        self._health: wire.Health | None = None
        self._said_error = ""
        self.gone = ""
        self.sim_mocap = None
        if sim_mocap is not None:  # the service's working folder is not this one
            truth, folder = sim_mocap
            named = not Path(truth).exists()  # a profile's name, else its file
            self.sim_mocap = (
                truth if named else str(Path(truth).resolve()),
                str(Path(folder).resolve()),
            )
        self.calibration: CalibrationBackend | None = LiveCalibration(self)

    # ------------------------------------------------------------ the service
    def send(self, message: Any) -> int:
        client = self._client
        if client is None:
            raise CdprError("not connected: pick a port on the link screen")
        return client.send(message)

    def command(self, message: Any) -> None:
        client = self._client
        if client is not None:
            client.command(message)

    def answer_now(self, number: int) -> Any:
        with self._cond:
            return self._answers.get(number)

    def ask(self, message: Any, timeout_s: float | None = None) -> Any:
        """Send a request and wait for its answer (None: none in ``timeout_s``). A connection
        closed meanwhile (``disconnect``, another ``connect``) ends the wait: its answers
        are dropped unread."""
        client = self._client
        number = self.send(message)

        def over() -> bool:
            return number in self._answers or bool(self.gone) or self._client is not client

        with self._cond:
            self._cond.wait_for(over, timeout_s)
            answer = self._answers.pop(number, None)
        if answer is None and self.gone:
            raise CdprError(f"the printer service went away ({self.gone})")
        if answer is None and self._client is not client:
            raise CdprError("the connection to the printer service was closed")
        return answer

    def operate(self, message: Any) -> wire.DeviceState | None:
        """A device operation: the device's status after it, or CdprError with the reason
        (a status unanswered in ``STATUS_TIMEOUT_S`` too: the UI never waits forever)."""
        timeout = STATUS_TIMEOUT_S if isinstance(message, wire.Status) else None
        answer = self.ask(message, timeout_s=timeout)
        if answer is None:
            raise CdprError("the printer service did not answer a status request")
        if not answer.ok:
            if "not homed" in answer.error:
                raise NotHomed(answer.error)
            raise CdprError(answer.error)
        if answer.status is not None:  # the newest status, for the screens
            self._device = (time.monotonic(), wire.DeviceMsg(connected=True, status=answer.status))
        return cast("wire.DeviceState | None", answer.status)

    def _read_loop(self, client: service_client.ServiceClient) -> None:
        while True:
            message = client.inbox.get()
            if client is not self._client:  # an old connection's last words
                if message is None:
                    return
                continue
            if message is None:
                with self._cond:
                    self.gone = client.gone or "it closed the connection"
                    self._cond.notify_all()
                return
            self._take(message)

    def _take(self, message: Any) -> None:
        if isinstance(message, wire.EventMsg):
            event = wire.event_from_json(message.event)
            job = self._job
            if job is not None:
                job.feed(event)
            else:
                self._replayed.append(event)
        elif isinstance(message, wire.Answer | wire.Reply):
            if message.id:
                with self._cond:
                    self._answers[message.id] = message
                    self._cond.notify_all()
            if not message.ok and not message.id:
                self._say("error", message.error)
        elif isinstance(message, wire.ResultMsg):
            self._device = None  # the job moved the device: what was seen before is old
            job = self._job
            if job is not None:
                job.finish(message)
                self._job = None
            self._replayed.clear()
            self._job_info = None  # over: nothing left to adopt
        elif isinstance(message, wire.DeviceMsg):
            self._device = (time.monotonic(), message)
            if message.health is not None:
                self._health = message.health
            if message.error and message.error != self._said_error:  # once, not every poll
                self._say("error", f"the device does not answer: {message.error}")
            self._said_error = message.error
        elif isinstance(message, wire.Note):
            self._say(message.kind, message.text)
        elif isinstance(message, wire.LogMsg):
            self._say("notice", message.text)
        elif isinstance(message, wire.JobInfo):
            self._job_info = message
            self._replayed.clear()

    def _say(self, kind: str, text: str) -> None:
        self._log.append(ConsoleLine(kind, text, time.time()))

    # ------------------------------------------------------------ link
    def ports(self) -> list[PortChoice]:
        return self.local.ports()

    def connect(self, port: str, baud: int) -> tuple[tuple[str, str], ...]:
        self.disconnect()
        client = self.attach(None if port == EMBEDDED else port, "tui", replay=True)
        with self._cond:
            self._answers.clear()
        self.gone, self._client, self._where = "", client, (port, baud)
        self._device, self._job, self._job_info, self._health = None, None, None, None
        self._replayed = []
        threading.Thread(
            target=self._read_loop, args=(client,), name="tui-service", daemon=True
        ).start()
        answer = self.ask(
            wire.Connect(
                profile=self.profile.model_dump(mode="json"),
                baud=baud if port != EMBEDDED else None,
                speedup=self.speedup if port == EMBEDDED else None,
            ),
            timeout_s=120.0,
        )
        if answer is None or not answer.ok or answer.identity is None:
            self.disconnect()
            raise CdprError(answer.error if answer is not None else "the service did not answer")
        if answer.status is not None:
            self._device = (time.monotonic(), wire.DeviceMsg(connected=True, status=answer.status))
        self._identity = identity_rows(
            SimpleNamespace(**answer.identity),
            port,
            baud,
            answer.identity.get("total_step_rate"),
        )
        self.local.announced = announced_board(answer.identity)
        return self._identity

    def disconnect(self) -> None:
        with self._cond:
            client, self._client = self._client, None
            self._cond.notify_all()  # the asks waiting on it: no answer comes now
        self.local.announced = None
        if client is None:
            return
        with contextlib.suppress(CdprError, OSError):
            client.send(wire.Disconnect())
        client.close()

    @property
    def let_go(self) -> bool:
        """This UI closed its connection to the service (a print there goes on)."""
        return self._client is None

    def connected(self) -> bool:
        return self._client is not None and not self.gone

    def machine_rate(self) -> float:
        embedded = self._where[0] == EMBEDDED
        return float(self.speedup) if embedded and self.speedup else 1.0

    def link_health(self) -> LinkHealth | None:
        h = self._health
        if h is None or not self.connected():
            return None
        return LinkHealth(retransmits=h.retransmits, bad_frames=h.bad_frames, naks=h.naks)

    def device_status(self) -> DeviceStatusView | None:
        if not self.connected():
            if self.gone:
                raise CdprError(f"the printer service went away ({self.gone})")
            return None
        seen = self._device
        if seen is not None and time.monotonic() - seen[0] < FRESH_S:
            if seen[1].error:
                raise CdprError(seen[1].error)
            if seen[1].status is not None:
                return status_view(self.model, seen[1].status)
        st = self.operate(wire.Status())
        return None if st is None else status_view(self.model, st)

    def status_while_busy(self) -> DeviceStatusView | None:
        seen = self._device
        if seen is None or seen[1].status is None or time.monotonic() - seen[0] > FRESH_S:
            return None
        return status_view(self.model, seen[1].status)

    def device_log(self) -> list[ConsoleLine]:
        out = []
        while self._log:
            out.append(self._log.popleft())
        return out

    # ------------------------------------------------------------ files
    def preflight(self, path: str) -> PreflightView:
        return self.local.preflight(path)

    def toggle_center(self) -> bool:
        return self.local.toggle_center()

    def find_resume(self, path: str) -> ResumeView | None:
        return self.local.find_resume(path)

    def diagnose(self, session_dir: str) -> DiagnosisView:
        return self.local.diagnose(session_dir)

    def diagnosed_write_plan(self) -> Any:
        return self.local.diagnosed_write_plan()

    def write_diagnosed_profile(self) -> str:
        return self.local.write_diagnosed_profile()

    # ------------------------------------------------------------ calibrate
    def wizard_device(self, settle_s: float) -> Any:
        """The wizard's device: its moves in the service's device session."""
        from cdprhost.tui.control.service_calibration import ServiceWizardDevice

        if not self.connected():
            raise CdprError("not connected: pick a port on the link screen")
        return ServiceWizardDevice(self, settle_s)

    def virtual_mocap(self) -> str | None:
        """The virtual motion capture's folder; it watches the service's embedded device
        from now on (None: none, or not on the embedded device)."""
        from cdprhost.tui.control.service_calibration import answered

        if self.sim_mocap is None or self._where[0] != EMBEDDED:
            return None
        truth, folder = self.sim_mocap
        answered(self, wire.Observe(truth=truth, mocap_dir=folder))
        return folder

    def simulated_camera(self, size: tuple[int, int]) -> Any:
        """The simulated camera watching the service's embedded device."""
        from cdprhost.errors import InputError
        from cdprhost.tui.control.service_calibration import ServiceCamera

        if not self.connected() or self._where[0] != EMBEDDED:
            raise InputError(
                "camera sim watches the embedded simulated device: connect to it first"
            )
        return ServiceCamera(self, size)

    # ------------------------------------------------------------ print
    def make_job(
        self,
        path: str,
        on_event: EventSink,
        resume_from_layer: int | None = None,
        resume: bool = False,
        clear_fault: bool = False,
    ) -> ServiceJob:
        from cdprhost.job.resume import log_path_for

        port, baud = self._where
        embedded = port == EMBEDDED
        spec = wire.StartJob(
            gcode=str(Path(path).resolve()),
            profile=self.profile.model_dump(mode="json"),
            port=None if embedded else port,
            baud=None if embedded else baud,
            speedup=self.speedup if embedded else None,
            setup=self.local.setup.to_json(),
            resume=resume,
            resume_from_layer=resume_from_layer,
            log_path=str(log_path_for(path).absolute()),
            clear_fault=clear_fault,
        )
        job = ServiceJob(self, on_event, wire.Start(job=spec))
        self._job = job
        return job

    def running_job(self, on_event: EventSink) -> tuple[str, float, ServiceJob] | None:
        """The print the service was running when this UI attached, as a job this UI follows
        (its events so far first): (file, started at, job); None when none runs."""
        info = self._job_info
        if info is None or info.state in ("none", "done", "failed", "cancelled", "refused"):
            return None
        if self._job is not None and not self._job.ended.is_set():
            return None  # this UI's own (its state reads idle until the first event arrives)
        job = ServiceJob(self, on_event, None)
        for event in self._replayed:
            job.feed(event)
        self._replayed = []
        self._job = job
        return info.gcode, info.started_at, job

    # ------------------------------------------------------------ device
    def _view(self, message: Any) -> DeviceStatusView:
        st = self.operate(message)
        if st is None:
            raise CdprError("the device did not report its status")
        return status_view(self.model, st)

    def jog_to(self, target: tuple[float, float, float]) -> DeviceStatusView:
        return self._view(wire.MoveTo(target=target, feed_mm_s=JOG_SPEED_MM_S))

    def home(self) -> DeviceStatusView:
        return self._view(wire.Home())

    def motors_off(self) -> DeviceStatusView:
        return self._view(wire.MotorsOff())

    def set_heaters(self, hotend_c: float, bed_c: float) -> DeviceStatusView:
        return self._view(wire.Heaters(hotend=hotend_c, bed=bed_c))

    def emergency_stop(self) -> bool:
        answer = self.ask(wire.Estop(), timeout_s=5.0)
        self._device = None  # what was seen before the stop is old news
        if answer is None:
            return False
        if not answer.ok:
            raise CdprError(answer.error)
        return bool(getattr(answer, "confirmed", True))

    def console(self, line: str) -> list[ConsoleLine]:
        from cdprhost.tui.control.live_console import run_console

        if not self.connected():
            return [
                ConsoleLine("sent", line, time.time()),
                ConsoleLine("error", "not connected: pick a port on the link screen"),
            ]
        machine = cast("Any", RemoteMachine(self))
        out = run_console(
            line, machine, lambda st: status_view(self.model, st), self._identity, JOG_SPEED_MM_S
        )
        return out + self.device_log()

    def close(self) -> None:
        self.disconnect()


def announced_board(identity: dict[str, Any]) -> Any:
    """What the service's device announced (a DeviceRecord: its step rate and shortest
    segment) for the preflight's estimate, as an in-process link gives it; None: nothing."""
    from cdprhost.job.board import announced_record
    from cdprhost.link.events import DeviceCaps

    ticks, total = identity.get("min_segment_ticks"), identity.get("total_step_rate")
    caps = (
        None
        if ticks is None
        else DeviceCaps(
            min_segment_ticks=int(ticks),
            total_step_rate=None if total is None else int(total),
        )
    )
    try:
        return announced_record(cast("Any", SimpleNamespace(**identity)), caps)
    except (TypeError, ValueError):  # an identity without the figures (another device)
        return None
