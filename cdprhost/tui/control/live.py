"""The UI backend on the real layers: host link, print job, preflight, calibration, diagnosis.

Every method that talks to the device or computes runs in a worker thread (see
:mod:`cdprhost.tui.control.backend`); the link itself is thread-safe. While a
print runs, the job owns the link: the UI only reads its counters.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.job.state import LinkHealth
from cdprhost.kinematics import MachineModel
from cdprhost.machine import Machine, NotHomed
from cdprhost.profile import MachineProfile, load_profile
from cdprhost.tui.control.backend import EMBEDDED, EventSink, JobHandle
from cdprhost.tui.control.views import (
    DeviceStatusView,
    DiagnosisView,
    PortChoice,
    PreflightView,
    ViolationRow,
)

ALL_MODULES = 0b111
JOG_SPEED_MM_S = 40.0


def identity_rows(identity: Any, port: str, baud: int) -> tuple[tuple[str, str], ...]:
    """The device identity as (key, value) rows for the connection screen."""
    rows = [
        ("port", port if port != EMBEDDED else "embedded simulated device"),
        ("firmware", f"{identity.firmware_name} {identity.firmware_version}"),
        ("protocol", ".".join(str(v) for v in identity.protocol)),
        ("axes", str(identity.axes)),
        ("queue capacity", f"{identity.queue_capacity} items"),
        ("clock", f"{identity.clock_hz:,} Hz"),
        ("max step rate", f"{identity.max_step_rate:,} steps/s"),
        ("heaters / fans", f"{identity.heaters} / {identity.fans}"),
        ("boot id", str(identity.boot_id)),
    ]
    if port != EMBEDDED:
        rows.insert(1, ("baud", str(baud)))
    return tuple(rows)


def preflight_view(report: Any, path: str) -> PreflightView:
    """A :class:`cdprhost.preflight.PreflightReport` as the print screen shows it."""
    violations = tuple(
        ViolationRow(v.line, v.rule, v.detail, tuple(v.point)) for v in report.violations
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
    ):
        self.profile = load_profile(profile) if isinstance(profile, str) else profile
        self.profile_name = self.profile.name
        self.model = MachineModel.from_profile(self.profile)
        self.speedup = speedup
        self.sim_options = dict(sim_options or {})
        self.diagnosis_settings = diagnosis_settings
        self.job_options = dict(job_options or {})
        self.idle_pump_s = idle_pump_s
        self._link: Any = None
        self._embedded = False
        self._where: tuple[str, int] | None = None
        self._lock = threading.RLock()
        from cdprhost.tui.control.live_calibration import LiveCalibration

        self.calibration = LiveCalibration(self)

    # ---------------------------------------------------------------- link
    @property
    def link(self) -> Any:
        if self._link is None:
            raise CdprError("not connected: pick a port on the connection screen (F1)")
        return self._link

    def ports(self) -> list[PortChoice]:
        speed = "as fast as possible" if not self.speedup else f"{self.speedup:g}x real time"
        choices = [PortChoice(EMBEDDED, "embedded simulated device", speed)]
        try:
            from serial.tools import list_ports

            for p in sorted(list_ports.comports(), key=lambda p: p.device):
                choices.append(
                    PortChoice(p.device, p.device, p.description if p.description != "n/a" else "")
                )
        except Exception:  # noqa: BLE001, S110 - a broken port enumeration must not hide the simulator
            pass
        return choices

    def connect(self, port: str, baud: int) -> tuple[tuple[str, str], ...]:
        from cdprhost.link import open_link
        from cdprhost.sim.embedded import open_embedded

        self.disconnect()
        if port == EMBEDDED:
            link = open_embedded(
                speedup=self.speedup, timeout_s=self.profile.serial.timeout_s, **self.sim_options
            )
            observer = self.sim_options.get("observer")
            if observer is not None and hasattr(observer, "attach_record"):
                observer.attach_record(
                    link.device.record
                )  # directions of motion for the truth's backlash
        else:
            link = open_link(port, baud, self.profile.serial.timeout_s)
        with self._lock:
            self._link, self._embedded, self._where = link, port == EMBEDDED, (port, baud)
        return identity_rows(link.identity, port, baud)

    def disconnect(self) -> None:
        with self._lock:
            link, self._link = self._link, None
        if link is not None:
            link.close()

    def connected(self) -> bool:
        return self._link is not None

    def link_health(self) -> LinkHealth | None:
        link = self._link
        if link is None:
            return None
        c = link.counters
        return LinkHealth(retransmits=c.retransmits, bad_frames=c.bad_frames, naks=c.naks_received)

    def device_status(self) -> DeviceStatusView | None:
        link = self._link
        if link is None:
            return None
        # The embedded device lives on a virtual clock that only runs while the link is
        # pumped: keep it going between status requests (paced to the speed-up).
        pump = self.idle_pump_s * (self.speedup or 1.0) if self._embedded else 0.0
        link.poll(pump)
        return self._status_view(link.request_status())

    def _status_view(self, st: Any) -> DeviceStatusView:
        steps = tuple(int(v) for v in st.steps)
        sliders = self.model.sliders_from_steps(np.asarray(steps[:3]))
        homed = st.homed_mask & ALL_MODULES == ALL_MODULES
        position = None
        if homed:
            p = self.model.fk(sliders[None, :])[0]
            position = tuple(float(v) for v in p) if np.all(np.isfinite(p)) else None
        return DeviceStatusView(
            steps,
            tuple(float(v) for v in sliders),
            position,
            st.hotend_c,
            st.bed_c,
            st.hotend_target_c,
            st.bed_target_c,
            bool(st.enabled_mask),
            homed,
            st.queue_free,
        )

    # --------------------------------------------------------------- print
    def preflight(self, path: str) -> PreflightView:
        from cdprhost.preflight import preflight

        return preflight_view(preflight(path, self.profile, self.model), path)

    def make_job(
        self, path: str, on_event: EventSink, resume_from_layer: int | None = None
    ) -> JobHandle:
        try:
            from cdprhost.job.runner import PrintJob, PrintOptions
        except ImportError as exc:  # the runner is a separate piece of work
            raise CdprError(f"the print runner is not available: {exc}") from None
        self.link  # noqa: B018 - raises when not connected
        options = PrintOptions(resume_from_layer=resume_from_layer, **self.job_options)
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
            raise CdprError("the modules are not homed: home first (h)") from None

    def jog_to(self, target: tuple[float, float, float]) -> DeviceStatusView:
        return self.move_to(target)

    def home(self) -> DeviceStatusView:
        return self._status_view(self.machine.home())

    def motors_off(self) -> DeviceStatusView:
        return self._status_view(self.machine.motors_off())

    def set_heaters(self, hotend_c: float, bed_c: float) -> DeviceStatusView:
        return self._status_view(self.machine.set_heaters(hotend_c, bed_c))

    # ------------------------------------------------------------ diagnose
    def diagnose(self, session_dir: str) -> DiagnosisView:
        from cdprhost.tui.control.live_diagnosis import run_diagnosis

        return run_diagnosis(session_dir, self.model, self.diagnosis_settings)

    def close(self) -> None:
        self.disconnect()
