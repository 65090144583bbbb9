"""What the UI holds of things that live in the printer service: the print it follows
(:class:`ServiceJob`, as the controller drives a job) and the machine the console talks
to (:class:`RemoteMachine` with its :class:`RemoteLink`). Each only forwards to the
service session it is given (:class:`ServiceSession`, the UI backend of
:mod:`~cdprhost.tui.control.service_backend`) and waits for its answers there.
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

from cdprhost.errors import CdprError
from cdprhost.job.state import Event
from cdprhost.machine.faults import DeviceFaulted, refusal
from cdprhost.motion.override import check_percent
from cdprhost.profile import MachineProfile
from cdprhost.service import wire
from cdprhost.tui.control.backend import EventSink


class ServiceSession(Protocol):
    """What the proxies ask of the UI's session with the service."""

    profile: MachineProfile
    model: Any
    gone: str

    @property
    def let_go(self) -> bool: ...

    def send(self, message: Any) -> int: ...

    def command(self, message: Any) -> None: ...

    def answer_now(self, number: int) -> Any: ...

    def ask(self, message: Any, timeout_s: float | None = None) -> Any: ...

    def operate(self, message: Any) -> wire.DeviceState | None: ...

    def emergency_stop(self) -> bool: ...


class ServiceJob:
    """A print in the service, as the controller drives a job: ``run`` blocks until the
    service sends its result; the requests are sent at once."""

    def __init__(self, service: ServiceSession, on_event: EventSink, start: wire.Start | None):
        self.service = service
        self.on_event = on_event
        self.start = start
        self.result: wire.ResultMsg | None = None
        self.ended = threading.Event()

    def feed(self, event: Event) -> None:
        self.on_event(event)

    def finish(self, result: wire.ResultMsg) -> None:
        self.result = result
        self.ended.set()

    def run(self) -> Any:
        start_id = self.service.send(self.start) if self.start is not None else None
        while not self.ended.wait(0.2):
            if start_id is not None:
                refused = self.service.answer_now(start_id)
                if refused is not None and not refused.ok:
                    raise CdprError(refused.error)
            if self.service.gone:
                raise CdprError(f"the printer service went away ({self.service.gone})")
            if self.service.let_go:  # the UI quits and leaves the print to the service
                raise CdprError("this UI let go of the print; it goes on in the printer service")
        assert self.result is not None
        if self.result.result is None:
            raise CdprError(self.result.error or "the print job broke")
        return self.result.result

    def request_pause(self) -> None:
        self.service.command(wire.Pause())

    def request_resume(self) -> None:
        self.service.command(wire.Resume())

    def request_cancel(self) -> None:
        self.service.command(wire.Cancel(reason="cancelled at the terminal UI"))

    def request_speed(self, percent: float) -> None:
        """M220 S<percent> for the print in the service; ValueError outside 10-500 %."""
        check_percent("speed", percent)
        self.service.command(wire.Override(what="speed", percent=percent))

    def request_flow(self, percent: float) -> None:
        """M221 S<percent> for the print in the service."""
        check_percent("flow", percent)
        self.service.command(wire.Override(what="flow", percent=percent))

    def emergency_stop(self) -> bool:
        answer = self.service.ask(wire.Estop(), timeout_s=5.0)
        return bool(answer is not None and answer.ok)


class RemoteLink:
    """What the console asks of a machine's link, through the service."""

    def __init__(self, service: ServiceSession):
        self.service = service

    def clear_fault(self) -> None:
        self.service.operate(wire.ClearFault())

    def wait_idle(self, timeout_s: float) -> None:
        """The service waited already (``heaters`` with ``wait``)."""


class RemoteMachine:
    """The machine operations the console uses, carried out by the service; each answers
    the device's status (a :class:`wire.DeviceState`)."""

    def __init__(self, service: ServiceSession):
        self.service = service
        self.profile = service.profile
        self.model = service.model
        self.link = RemoteLink(service)

    def home(self) -> Any:
        return self.service.operate(wire.Home())

    def enable(self) -> Any:
        return self.service.operate(wire.Enable())

    def motors_off(self) -> Any:
        return self.service.operate(wire.MotorsOff())

    def status(self) -> Any:
        return self.service.operate(wire.Status())

    def ready(self) -> Any:
        """The device's status when it can take a command; a faulted device is refused
        here, nothing sent, with the fault and the way out (as ``Machine.ready``)."""
        state = self.status()
        if state is not None and state.fault:
            raise DeviceFaulted(refusal(state.fault, state.clearable))
        return state

    def emergency_stop(self) -> bool:
        return self.service.emergency_stop()

    def set_heaters(
        self, hotend_c: float | None = None, bed_c: float | None = None, *, wait: bool = False
    ) -> Any:
        return self.service.operate(wire.Heaters(hotend=hotend_c, bed=bed_c, wait=wait))

    def move_to(self, target: tuple[float, float, float], feed_mm_s: float) -> Any:
        return self.service.operate(wire.MoveTo(target=target, feed_mm_s=feed_mm_s))
