"""A scripted backend for headless UI tests: no link, no device, full control of timing."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np

from cdprhost.job.state import (
    Failure,
    JobState,
    LinkHealth,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
)
from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.views import (
    CalibrationView,
    CandidateRow,
    ConsoleLine,
    DeviceStatusView,
    DiagnosisView,
    IdentificationView,
    ParameterRow,
    PortChoice,
    PoseView,
    PreflightView,
    ResumeView,
    ViolationRow,
)


class FakeJob:
    """Emits a plausible job: preflight, heating, ``segments`` moves over ``layers`` layers.

    ``gate`` (a semaphore) lets a test release segments one by one; ``fail_at``
    makes the device "reset" after that many segments.
    """

    def __init__(
        self,
        on_event,
        *,
        segments=30,
        layers=3,
        gate=None,
        fail_at=None,
        start_line=10,
        rest_every=1,
        resume_from_layer=None,
    ):
        self.on_event, self.segments, self.layers = on_event, segments, layers
        self.gate, self.fail_at, self.start_line = gate, fail_at, start_line
        self.rest_every = rest_every  # pause/cancel take effect only after these many segments
        self.resume_from_layer = resume_from_layer
        self._pause, self._resume, self._cancel = (
            threading.Event(),
            threading.Event(),
            threading.Event(),
        )
        self.result = None
        self.reason = ""
        self.ended = threading.Event()
        self.estops = 0

    def request_pause(self):
        self._pause.set()

    def request_resume(self):
        self._resume.set()

    def request_cancel(self, reason=""):
        self.reason = reason
        self._cancel.set()
        self._resume.set()

    # the safe-stop API of cdprhost.job.runner.PrintJob
    @property
    def finished(self):
        return self.ended.is_set()

    def wait(self, timeout_s=None):
        return self.ended.wait(timeout_s)

    def emergency_stop(self):
        self.estops += 1
        self.reason = "emergency stop"
        self._cancel.set()
        self._resume.set()
        return True

    def shutdown(self, reason="quit", timeout_s=10.0):
        if self.finished:
            return True
        self.request_cancel(reason)
        if self.wait(timeout_s):
            return True
        self.emergency_stop()
        return self.wait(2.0)

    def _state(self, s, reason=""):
        self.on_event(StateChanged(s, reason))

    def run(self):
        try:
            self.result = self._run()
            return self.result
        finally:
            self.ended.set()

    def _run(self):
        emit = self.on_event
        self._state(JobState.PREFLIGHT)
        emit(
            Planned(
                layers=self.layers,
                moves=self.segments,
                estimated_time_s=60.0,
                filament_mm=12.5,
                segments=self.segments,
            )
        )
        self._state(JobState.HEATING)
        emit(Temperatures(200.0, 60.0, 200.0, 60.0))
        self._state(JobState.PRINTING)
        per_layer = max(self.segments // self.layers, 1)
        for i in range(1, self.segments + 1):
            at_rest = (i - 1) % self.rest_every == 0
            if self.gate is not None:
                while not self.gate.acquire(timeout=0.05):
                    if at_rest and (self._cancel.is_set() or self._pause.is_set()):
                        break
            if at_rest and self._pause.is_set() and not self._cancel.is_set():
                self._state(JobState.PAUSING)
                self._state(JobState.PAUSED)
                self._resume.wait(timeout=30)
                self._pause.clear()
                self._resume.clear()
                if not self._cancel.is_set():
                    self._state(JobState.PRINTING)
                if self.gate is not None:
                    self.gate.acquire(timeout=30)
            if at_rest and self._cancel.is_set():
                self._state(JobState.CANCELLING)
                if self.reason == "emergency stop":
                    self._state(JobState.FAILED, "emergency stop")
                    return "failed"
                self._state(
                    JobState.CANCELLED, f"cancelled: {self.reason}" if self.reason else "cancelled"
                )
                return "cancelled"
            if self.fail_at is not None and i > self.fail_at:
                layer = (i - 2) // per_layer
                emit(
                    Failure(
                        "device reset (boot id changed)",
                        self.start_line + i - 1,
                        layer,
                        (1.0, 2.0, 120.0),
                        "/tmp/resume.json",
                    )
                )
                self._state(JobState.FAILED, "device reset")
                return "failed"
            t = i * 2.0
            emit(
                Progress(
                    i,
                    self.start_line + i,
                    min((i - 1) // per_layer, self.layers - 1),
                    t,
                    position=(float(i), 0.5 * i, 110.0 + 0.2 * ((i - 1) // per_layer)),
                    sliders=(-0.1 * i, 0.05 * i, 0.02 * i),
                    tensions=(40.0 + i, 45.0, 50.0),
                    steps=(-40 * i, 20 * i, 8 * i, 95 * i),
                )
            )
            emit(Temperatures(200.0 + (i % 3) * 0.5, 60.0, 200.0, 60.0))
            emit(LinkHealth(retransmits=i // 10, bad_frames=i // 15))
        self._state(JobState.DONE)
        return "completed"


class FakeCalibration:
    def __init__(self, backend):
        self.backend = backend
        self.moved: list[int] = []

    def plan(self, n_fit, n_check, session_dir, mocap_config=None):
        self.mocap_config = mocap_config
        pts = [(-20.0 + 10 * i, 5.0 * i, 150.0 + 20 * i) for i in range(n_fit + n_check)]
        poses = tuple(
            PoseView(i + 1, p, "fit" if i < n_fit else "check") for i, p in enumerate(pts)
        )
        return CalibrationView(
            "planned",
            poses,
            None,
            session_dir or "/tmp/session",
            (("O1", 0.41), ("O2", 0.052), ("O3", 0.021)),
            None,
            "",
        )

    def move_to(self, pose):
        self.moved.append(pose.index)
        return replace(pose, status="settled", detail="settled")

    def ingest(self, pose, take_path):
        if "bad" in take_path:
            return replace(
                pose, status="rejected", detail=f"{take_path}: effector not static (spread 0.9 mm)"
            )
        return replace(pose, status="take ok", detail="base fit 0.02 mm", measured=pose.point)

    def identify(self):
        rows = tuple(
            ParameterRow(
                f"A{k // 3 + 1}.{'xyz'[k % 3]}", 100.0 + k, 100.5 + k, 0.01, 100.48 + k, 100.52 + k
            )
            for k in range(9)
        )
        rows += tuple(
            ParameterRow(f"L{k + 1}0", 390.0, 391.2, 0.02, 391.16, 391.24) for k in range(3)
        )
        return IdentificationView(rows, 14.2, 0.051, 5, 4, 12.0, 0.07, (), "/tmp/calibrated.toml")


class FakeBackend:
    """Implements the Backend protocol without hardware; ``job_kwargs`` shape the FakeJob."""

    def __init__(self, profile="paper-prototype", **job_kwargs):
        self.profile_name = profile
        self.profile = load_profile(profile)
        self.model = MachineModel.from_profile(self.profile)
        self.job_kwargs = job_kwargs
        self.jobs: list[FakeJob] = []
        self.calibration = FakeCalibration(self)
        self._connected = False
        self.moves: list[tuple[float, float, float]] = []
        self.status = self._status_at(self.model.home_point(np.zeros(3)))
        self.preflight_views: dict[str, PreflightView] = {}
        self.resume_points: dict[str, ResumeView] = {}
        self.link_dead = False  # device_status raises (a port that vanished)
        self.log: list[ConsoleLine] = []
        self.sent: list[str] = []
        self.estops = 0
        self.busy_status_asks = 0
        self.closed_after_jobs: list[bool] | None = None
        self.rate = 1.0
        self.now = 1_750_000_000.0  # the wall clock of the console's replies

    def _status_at(self, point):
        p = np.asarray(point, dtype=float)[None, :]
        s = self.model.ik(p)[0]
        steps = tuple(int(v) for v in self.model.steps(s[None, :])[0]) + (0,)
        return DeviceStatusView(
            steps,
            tuple(float(v) for v in s),
            tuple(float(v) for v in p[0]),
            25.0,
            25.0,
            0.0,
            0.0,
            True,
            True,
            64,
        )

    def ports(self):
        return [
            PortChoice(EMBEDDED, "embedded simulated device", "accelerated"),
            PortChoice("/dev/ttyFAKE0", "/dev/ttyFAKE0", "USB serial"),
        ]

    def connect(self, port, baud):
        if port != EMBEDDED:
            raise OSError(f"{port}: no such device")
        self._connected = True
        self.link_dead = False
        return (
            ("firmware", "cdpr-sim 0.1"),
            ("protocol", "1"),
            ("queue", "64 segments"),
            ("port", port),
            ("baud", str(baud)),
        )

    def disconnect(self):
        self._connected = False

    def connected(self):
        return self._connected

    def link_health(self):
        return LinkHealth(0, 0) if self._connected else None

    def device_status(self):
        if self.link_dead:
            raise OSError("the port failed on read (was it unplugged?)")
        return self.status if self._connected else None

    def status_while_busy(self):
        self.busy_status_asks += 1
        return self.status if self._connected else None

    def machine_rate(self):
        return self.rate

    def device_log(self):
        out, self.log = self.log, []
        return out

    def find_resume(self, path):
        return self.resume_points.get(path)

    def emergency_stop(self):
        self.estops += 1
        self.status = replace(self.status, hotend_target=0.0, bed_target=0.0)
        return True

    def console(self, line):
        self.sent.append(line)
        now = self.now
        if line.strip().upper() == "M105":
            return [
                ConsoleLine("sent", line, now),
                ConsoleLine("reply", "hotend 25.0 / 0.0 °C", now),
            ]
        return [
            ConsoleLine("sent", line, now),
            ConsoleLine("error", f"{line.split()[0]} is not a console command", now),
        ]

    def preflight(self, path):
        if path in self.preflight_views:
            return self.preflight_views[path]
        if "bad" in path:
            return PreflightView(
                path,
                False,
                (
                    ViolationRow(
                        12, "build_volume", "outside the build volume by 30 mm", (0, 0, 400)
                    ),
                    ViolationRow(15, "unknown_command", "M999 is not understood"),
                ),
                20,
                2,
                30.0,
                3.0,
            )
        return PreflightView(path, True, (), 30, 3, 60.0, 12.5, (), self._toolpath(path))

    def _toolpath(self, path):
        from cdprhost.motion.program import read_items
        from cdprhost.tui.control.toolpath import ToolpathTap

        tap = ToolpathTap(tuple(self.profile.build_volume.bed_origin))
        for _ in tap.tap(read_items(path, self.profile, self.model)):
            pass
        return tap.result()

    def make_job(self, path, on_event, resume_from_layer=None, resume=False, clear_fault=False):
        self.cleared_fault = clear_fault
        if self.link_dead:
            raise OSError("the port failed on write (was it unplugged?)")
        job = FakeJob(on_event, resume_from_layer=resume_from_layer, **self.job_kwargs)
        job.resume_exact = resume
        self.jobs.append(job)
        return job

    def jog_to(self, target):
        self.moves.append(tuple(target))
        self.status = self._status_at(target)
        return self.status

    def home(self):
        self.status = self._status_at(self.model.home_point(np.zeros(3)))
        return self.status

    def motors_off(self):
        self.status = replace(self.status, motors_on=False)
        return self.status

    def set_heaters(self, hotend_c, bed_c):
        self.status = replace(self.status, hotend_target=hotend_c, bed_target=bed_c)
        return self.status

    def diagnose(self, session_dir):
        if "missing" in session_dir:
            raise FileNotFoundError(f"{session_dir}/session.toml: no such file")
        before = tuple(0.1 + 0.02 * (k % 7) for k in range(40))
        after = tuple(0.06 + 0.005 * (k % 5) for k in range(40))
        return DiagnosisView(
            "named",
            "cable_elasticity",
            "cable residuals grow with tension (r = 0.91)",
            (
                CandidateRow("cable_elasticity", 1e-9, -42.0, 0.071),
                CandidateRow("drive_scale", 0.2, -1.0, 0.14),
                CandidateRow("backlash", 0.6, 3.0, 0.15),
                CandidateRow("drift", 0.8, 3.5, 0.15),
            ),
            0.152,
            0.071,
            0.066,
            before,
            after,
            (("EA", "18500 ± 900 N"),),
        )

    def close(self):
        self.closed_after_jobs = [job.finished for job in self.jobs]  # the link closes last
        self._connected = False
