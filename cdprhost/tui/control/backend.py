"""The seam between the terminal UI and the layers below it.

The app talks to one :class:`Backend`. Every method marked *blocking* is called
from a Textual thread worker, never from the UI thread; non-blocking ones only
read counters. :mod:`cdprhost.tui.control.service_backend` implements it as a client of
the printer service (the print, the link and the machine in the service's process; what
``cdprhost tui`` uses), :mod:`cdprhost.tui.control.live` in this process on the real link,
print job, preflight, machine operations, calibration and diagnosis (``--in-process``);
the tests use fakes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from cdprhost.job.state import Event, LinkHealth
from cdprhost.kinematics import MachineModel
from cdprhost.profile import MachineProfile
from cdprhost.tui.control.views import (
    CalibrationView,
    ConsoleLine,
    DeviceStatusView,
    DiagnosisView,
    IdentificationView,
    PortChoice,
    PoseView,
    PreflightView,
    ResumeView,
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

    def plan(
        self,
        n_fit: int,
        n_check: int,
        session_dir: str | None,
        mocap_config: str | None = None,
        camera: str | None = None,  # a camera takes pictures instead of motion capture
        intrinsics: str | None = None,  # ... with these intrinsics (camera.toml)
    ) -> CalibrationView: ...

    def move_to(self, pose: PoseView) -> PoseView: ...

    def ingest(self, pose: PoseView, take_path: str) -> PoseView: ...

    def identify(self) -> IdentificationView: ...


class Backend(Protocol):
    profile_name: str
    profile: MachineProfile
    model: MachineModel
    calibration: CalibrationBackend | None

    def ports(self) -> list[PortChoice]:
        """Blocking (short): ports to offer, the embedded simulated device first."""

    def connect(self, port: str, baud: int) -> tuple[tuple[str, str], ...]:
        """Blocking: open the link and return the device identity as (key, value) rows."""

    def disconnect(self) -> None: ...

    def connected(self) -> bool: ...

    def machine_rate(self) -> float:
        """Non-blocking: machine seconds per wall second to expect before any is measured
        (1 on hardware, the speed-up of a simulated device)."""

    def link_health(self) -> LinkHealth | None:
        """Non-blocking: the link's counters, or None when not connected."""

    def device_status(self) -> DeviceStatusView | None:
        """Blocking (short): the device's latest status; raises when the link is dead."""

    def status_while_busy(self) -> DeviceStatusView | None:
        """Blocking (short): while an operation holds the link (homing, a jog, a heater
        wait), ask for a status without waiting for it and return the latest one received,
        if it is recent (the operation's own waiting reads the reply); else None."""

    def device_log(self) -> list[ConsoleLine]:
        """Non-blocking: what the device said since the last call (errors, resets)."""

    def preflight(self, path: str) -> PreflightView:
        """Blocking: check the file (placed as set); the view carries its toolpath."""

    def toggle_center(self) -> bool:
        """Centre files on the build volume (``--center``) or stop; True: centred now."""

    def find_resume(self, path: str) -> ResumeView | None:
        """Blocking (short): the resume point saved for this file (same content), if any."""

    def make_job(
        self,
        path: str,
        on_event: EventSink,
        resume_from_layer: int | None = None,
        resume: bool = False,
        clear_fault: bool = False,
    ) -> JobHandle:
        """A print job of ``path``: from the start, from ``resume_from_layer`` (0-based), or
        (``resume``) exactly at the file's saved resume point, like ``print --resume``;
        ``clear_fault``: the operator accepted clearing the device's fault (else a faulted
        device is refused)."""
        ...

    def jog_to(self, target: tuple[float, float, float]) -> DeviceStatusView: ...

    def home(self) -> DeviceStatusView: ...

    def motors_off(self) -> DeviceStatusView: ...

    def set_heaters(self, hotend_c: float, bed_c: float) -> DeviceStatusView: ...

    def emergency_stop(self) -> bool:
        """Blocking (short): stop now, bypassing the queue; True when the device confirmed."""

    def console(self, line: str) -> list[ConsoleLine]:
        """Blocking: carry out one console command; the reply lines."""

    def diagnose(self, session_dir: str) -> DiagnosisView: ...

    def close(self) -> None: ...
