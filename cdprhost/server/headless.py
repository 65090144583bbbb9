"""A printer that runs print jobs in this process, one at a time, on one link (the in-process
tests and benches; ``cdprhost serve`` runs its jobs in the printer service instead:
:mod:`cdprhost.server.service_printer`).

The link is opened at the first start and kept (the simulated device keeps its state between
jobs like a real one); a job finds it dead and it is opened again. Job events are folded into
one :class:`~cdprhost.job.state.JobSnapshot` the API reports. Pause, cancel and
:meth:`HeadlessPrinter.shutdown` go through :mod:`cdprhost.server.jobcontrol` (the safe stop).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from cdprhost.errors import CdprError
from cdprhost.job.before_start import before_start
from cdprhost.job.resume import log_path_for
from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import (
    Event,
    IllegalTransition,
    JobSnapshot,
    JobState,
    Temperatures,
    reduce,
    temperatures_of,
)
from cdprhost.kinematics.machine import MachineModel
from cdprhost.link import HostLink, LinkError
from cdprhost.link.errors import DeviceFault
from cdprhost.motion.prepared import Setup
from cdprhost.profile.models import MachineProfile
from cdprhost.server import jobcontrol
from cdprhost.server.printer import (
    PrinterStatus,
    Refused,
    refuse_if_busy,
    refuse_if_faulted,
    refuse_unless_preflight_passes,
)

log = logging.getLogger(__name__)

TEMPERATURE_MAX_AGE_S = 1.0  # a reading younger than this answers again (apps poll often)


class HeadlessPrinter:
    def __init__(
        self,
        profile: MachineProfile,
        open_link: Callable[[], HostLink],
        *,
        setup: Setup | None = None,
        job_options: dict[str, Any] | None = None,
        on_event: Callable[[Event], None] | None = None,
        clear_fault: bool = False,
    ):
        """``clear_fault``: a device fault is cleared at a start (someone checked the
        machine); by default a faulted device refuses the start (409, the fault explained)."""
        self.profile = profile
        self.model = MachineModel.from_profile(profile)
        self.setup = setup or Setup()
        self.job_options = dict(job_options or {})
        self._open_link = open_link
        self.clear_fault = clear_fault
        self._link: HostLink | None = None
        self._lock = threading.RLock()
        self._status = PrinterStatus()
        self._job: PrintJob | None = None
        self._worker: threading.Thread | None = None
        self._closing = False
        self._listeners: list[Callable[[Event], None]] = [on_event] if on_event else []
        self._idle_temps: tuple[float, Temperatures] | None = None  # (monotonic s, reading)

    # ------------------------------------------------------------ status
    def status(self) -> PrinterStatus:
        return self._status

    def _on_event(self, event: Event) -> None:
        with self._lock:
            try:
                job = reduce(self._status.job, event)
            except IllegalTransition as exc:
                log.warning("job event out of order: %s", exc)
                return
            ended = (
                time.time() if job.state.finished and not self._status.job.state.finished else None
            )
            self._status = replace(self._status, job=job, ended_at=ended or self._status.ended_at)
        for listener in self._listeners:
            listener(event)

    # ------------------------------------------------------------- start
    def check_start(self, path: Path) -> None:
        self._refuse_if_busy()
        refuse_unless_preflight_passes(path, self.profile, self.model, self.setup)
        self._refuse_if_faulted(path)

    def _refuse_if_faulted(self, path: Path) -> None:
        with self._lock:
            self._refuse_if_busy()
            try:
                info = before_start(self._job_link(), path)
            except (LinkError, OSError) as exc:
                raise Refused(f"the device does not answer: {exc}; nothing started") from None
        refuse_if_faulted(info.fault, info.clearable, self.clear_fault)

    def _refuse_if_busy(self) -> None:
        refuse_if_busy(self._status, self._closing)

    def start(self, path: Path, who: str) -> None:
        with self._lock:
            self._refuse_if_busy()
            options = PrintOptions(
                setup=self.setup,
                log_path=log_path_for(path),
                clear_fault=self.clear_fault,
                **self.job_options,
            )
            job = PrintJob(path, self.profile, self._job_link, options, self._on_event)
            self._status = PrinterStatus(
                connected=True,
                file=path,
                started_by=who,
                job=JobSnapshot(state=JobState.IDLE),
                started_at=time.time(),
            )
            self._job = job
            self._worker = threading.Thread(
                target=self._run, args=(job,), name="server-print-job", daemon=True
            )
            self._worker.start()
        log.info("print of %s started by %s", path.name, who)

    def _run(self, job: PrintJob) -> None:
        try:
            result = job.run()
            log.info("print of %s: %s %s", job.gcode.name, result.status, result.reason)
        except Exception:  # the job already stopped the machine; never kill the server
            log.exception("print job of %s raised", job.gcode.name)

    def connect(self) -> None:
        """Open the device now (``serve`` at start: a wrong port is said before anything
        listens). Raises the link's error."""
        with self._lock:
            self._job_link()

    def _job_link(self) -> HostLink:
        """The kept link, checked; opened (again) when there is none or it has failed."""
        link = self._link
        if link is not None:
            try:
                link.request_status(timeout=self.profile.serial.timeout_s)
                return link
            except DeviceFault:  # alive, and stopped by a fault: the start decides
                return link
            except (LinkError, OSError):
                self._close_link()
        self._link = self._open_link()
        return self._link

    def _close_link(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            try:
                link.close()
            except (LinkError, OSError) as exc:
                log.warning("closing the link: %s", exc)

    # ---------------------------------------------------------- controls
    def _active_job(self, what: str) -> PrintJob:
        job, worker = self._job, self._worker
        if job is None or worker is None or not worker.is_alive():
            state = self._status.job.state.value
            raise Refused(f"no print is running ({state}): nothing to {what}")
        return job

    def pause(self, action: str) -> None:
        job = self._active_job(action)
        state = self._status.job.state
        if action == "toggle":
            action = "resume" if state is JobState.PAUSED else "pause"
        if action == "pause":
            if state not in (JobState.PRINTING, JobState.HEATING):
                raise Refused(f"cannot pause while {state.value}")
            jobcontrol.pause(job)
        elif action == "resume":
            if state is not JobState.PAUSED:
                raise Refused(f"cannot resume while {state.value}")
            jobcontrol.resume(job)
        else:
            raise ValueError(f"unknown pause action {action!r}")

    def cancel(self) -> None:
        """Also while the job starts (preflight, connecting): it then ends before moving."""
        job = self._active_job("cancel")
        if self._status.job.state is JobState.CANCELLING:
            return
        jobcontrol.cancel(job)

    def emergency_stop(self) -> bool:
        """Stop now (a second signal while stopping): the job's e-stop, when one runs."""
        job = self._job
        return bool(job is not None and not job.finished and jobcontrol.emergency_stop(job))

    def run_idle(self, fn: Callable[[HostLink], Any]) -> Any:
        """Blocking: ``fn(link)`` on the device while no job runs (the web page's heaters off,
        home, jog and idle e-stop); Refused while a job runs or when the device does not answer."""
        with self._lock:
            self._refuse_if_busy()
            try:
                return fn(self._job_link())
            except (CdprError, LinkError, OSError) as exc:
                raise Refused(f"{exc}; nothing done") from None

    def uploaded(self, path: Path) -> None:
        log.info("stored upload %s", path)

    def temperatures(self) -> Temperatures | None:
        """The running job's newest reading; without a job, the device's (asked at most once
        a second; never while a start holds the link)."""
        status = self._status
        if status.busy:
            return status.job.temperatures
        now = time.monotonic()
        cached = self._idle_temps
        if cached is not None and now - cached[0] < TEMPERATURE_MAX_AGE_S:
            return cached[1]
        if not self._lock.acquire(blocking=False):
            return cached[1] if cached else status.job.temperatures
        try:
            link = self._link
            if link is None or self._status.busy:
                return status.job.temperatures
            try:
                reading = temperatures_of(
                    link.request_status(timeout=self.profile.serial.timeout_s)
                )
            except DeviceFault as exc:  # a faulted device still reports its heaters
                log.debug("status while faulted: %s", exc)
                return cached[1] if cached else None
            except (LinkError, OSError) as exc:
                log.warning("temperature reading: %s", exc)
                return None
            self._idle_temps = (now, reading)
            return reading
        finally:
            self._lock.release()

    # ---------------------------------------------------------- shutdown
    def wait_idle(self, timeout_s: float) -> bool:
        """Blocking: until no job runs (for tests and the CLI)."""
        worker = self._worker
        if worker is None:
            return True
        worker.join(timeout=timeout_s)
        return not worker.is_alive()

    def shutdown(self, reason: str = "server shutdown", timeout_s: float = 30.0) -> bool:
        """Blocking: refuse new starts, stop a running print safely, then close the link.
        True when no job was left running."""
        with self._lock:
            self._closing = True
            job, worker = self._job, self._worker
        ended = True
        if job is not None and worker is not None and worker.is_alive():
            log.warning("stopping the running print of %s (%s)", job.gcode.name, reason)
            ended = jobcontrol.shutdown(job, worker, reason, timeout_s)
        self._close_link()
        return ended
