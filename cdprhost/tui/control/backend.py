"""The seam between the terminal UI and the layers below it.

The app talks to one :class:`Backend`. Every method marked *blocking* is called
from a Textual thread worker, never from the UI thread; non-blocking ones only
read counters. :mod:`cdprhost.tui.control.live` implements it on the real link,
print job, preflight, calibration and diagnosis; the tests use fakes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from cdprhost.job.state import Event, LinkHealth
from cdprhost.kinematics import MachineModel
from cdprhost.profile import MachineProfile
from cdprhost.tui.control.views import (
    CalibrationView,
    DeviceStatusView,
    DiagnosisView,
    IdentificationView,
    PortChoice,
    PoseView,
    PreflightView,
)

EMBEDDED = "sim"
"""Port name of the embedded simulated device."""

EventSink = Callable[[Event], None]


@runtime_checkable
class JobHandle(Protocol):
    """A print job: ``run`` blocks until it ends; the requests are thread-safe."""

    def run(self) -> Any: ...

    def request_pause(self) -> None: ...

    def request_resume(self) -> None: ...

    def request_cancel(self) -> None: ...


class CalibrationBackend(Protocol):
    """The calibration wizard as the UI drives it (all blocking)."""

    def plan(self, n_fit: int, n_check: int, session_dir: str | None) -> CalibrationView: ...

    def move_to(self, pose: PoseView) -> PoseView: ...

    def ingest(self, pose: PoseView, take_path: str) -> PoseView: ...

    def identify(self) -> IdentificationView: ...


class Backend(Protocol):
    profile_name: str
    profile: MachineProfile
    model: MachineModel
    calibration: CalibrationBackend | None

    def ports(self) -> list[PortChoice]: ...

    def connect(self, port: str, baud: int) -> tuple[tuple[str, str], ...]:
        """Blocking: open the link and return the device identity as (key, value) rows."""

    def disconnect(self) -> None: ...

    def connected(self) -> bool: ...

    def link_health(self) -> LinkHealth | None:
        """Non-blocking: the link's counters, or None when not connected."""

    def device_status(self) -> DeviceStatusView | None:
        """Blocking (short): the device's latest status."""

    def preflight(self, path: str) -> PreflightView: ...

    def make_job(
        self, path: str, on_event: EventSink, resume_from_layer: int | None = None
    ) -> JobHandle: ...

    def jog_to(self, target: tuple[float, float, float]) -> DeviceStatusView: ...

    def home(self) -> DeviceStatusView: ...

    def motors_off(self) -> DeviceStatusView: ...

    def set_heaters(self, hotend_c: float, bed_c: float) -> DeviceStatusView: ...

    def diagnose(self, session_dir: str) -> DiagnosisView: ...

    def close(self) -> None: ...
