"""The print side of the controller: open a file, run a job, pause/cancel, resume a failed
print (after checking the link), and remember files and finished jobs.

Quitting (the quit key, SIGHUP/SIGTERM/SIGINT) while a job runs goes through the job's one
safe-stop path: the job is stopped like a cancel (stop within the buffered motion, park,
heaters off, resume point saved) and waited for, its record goes to the history, and only
then does the app exit and close the link."""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path
from typing import Any

from cdprhost.job.resume import resume_question
from cdprhost.job.state import JobSnapshot, JobState, StateChanged
from cdprhost.tui.control.backend import JobHandle
from cdprhost.tui.control.link_flow import ControllerBase
from cdprhost.tui.control.store import HISTORY_MAX
from cdprhost.tui.control.views import ConsoleLine, DeviceStatusView, JobRecord, ResumeView
from cdprhost.tui.state import FileView
from cdprhost.tui.tabs import screen_key

SHUTDOWN_TIMEOUT_S = 10.0
"""How long a quit waits for the job's controlled stop before an emergency stop."""


def shutdown_job(job: JobHandle, ended: threading.Event, reason: str, timeout_s: float) -> bool:
    """Blocking: stop ``job`` like a cancel and wait until its ``run`` returned (``ended``);
    True when it did. The job's own ``shutdown`` when it has one (it e-stops after
    ``timeout_s``), else a cancel request and a wait."""
    shutdown = getattr(job, "shutdown", None)
    if shutdown is not None:
        return bool(shutdown(reason, timeout_s=timeout_s)) and ended.wait(timeout_s)
    job.request_cancel()
    if ended.wait(timeout_s):
        return True
    stop = getattr(job, "emergency_stop", None)
    if stop is not None:
        stop()
    return ended.wait(2.0)


def job_record(state: Any, ended: float) -> JobRecord:
    """The history record of the job in ``state`` (a :class:`UiState`) as it ended."""
    job = state.job
    done = min(job.layer + 1, job.layers) if job.segments_done else 0
    status, reason = job.state.value, job.reason if job.state is not JobState.DONE else ""
    if not job.state.finished:  # quitting, and the job did not stop in time
        status, reason = "failed", reason or "the job did not stop in time"
    return JobRecord(
        state.job_path,
        status,
        state.job_started,
        ended,
        done,
        job.layers,
        reason,
        state.job_resumed_from,
    )


def _quiet(fn: Any) -> Any:
    try:
        return fn()
    except Exception:  # noqa: BLE001 - a best effort while stopping
        return None


class PrintFlow(ControllerBase):
    # ------------------------------------------------------------------ files
    def open_file(self, path: str) -> None:
        path = str(Path(path).expanduser())
        self.update(file=FileView(path=path, checking=True))
        backend, recent = self.backend, self.app.recent_files

        def work() -> tuple[Any, ResumeView | None, tuple[str, ...]]:
            view = backend.preflight(path)
            return view, backend.find_resume(path), recent.add(path)

        def done(result: tuple[Any, ResumeView | None, tuple[str, ...]]) -> None:
            view, resume, files = result
            if self.state.file.path == path:
                self.update(file=FileView(path=path, preflight=view, resume=resume), recent=files)
            else:
                self.update(recent=files)

        def fail(exc: BaseException) -> None:
            if self.state.file.path == path:
                self.update(file=FileView(path=path, error=str(exc) or type(exc).__name__))

        self.background("preflight", work, done, fail, exclusive=True)

    def toggle_center(self) -> None:
        """Centre the open file's part on the build volume (or stop) and check it again."""
        path = self.state.file.path
        if not path or self.state.job_active:
            return
        centred = self.backend.toggle_center()
        self.app.notify("part centred on the build volume" if centred else "part as sliced")
        self.open_file(path)

    def lookup_resume(self) -> None:
        """Look for a resume point of the open file again (after a job, after a reconnect)."""
        path = self.state.file.path
        if not path or self.state.file.preflight is None:
            return

        def done(resume: ResumeView | None) -> None:
            if self.state.file.path == path:
                self.update(file=replace(self.state.file, resume=resume))

        self.background(
            "resume-lookup", lambda: self.backend.find_resume(path), done, lambda _: None
        )

    def connected_again(self) -> None:
        self.lookup_resume()

    # -------------------------------------------------------------------- jobs
    def adopt_running_job(self) -> bool:
        """A print already running in the printer service this UI attached to (started by
        an earlier UI, ``cdprhost print`` or the upload server): shown and driven as if
        started here, its events so far first. True when there is one."""
        running = getattr(self.backend, "running_job", None)
        if running is None or self.state.job_active:
            return False
        job_id = self.state.job_id + 1
        sink = self.app.pump.sink(job_id)
        found = running(sink)
        if found is None:
            return False
        path, started_at, job = found
        self._status_gen += 1
        self.update(
            job=JobSnapshot(state=JobState.PREFLIGHT),  # active at once, as for :meth:`start`
            job_id=job_id,
            job_path=path,
            job_started=started_at or self.app.wall_clock(),
            job_ended=0.0,
            notice_at=None,
            job_resumed_from=None,
            job_resume_line=None,
            job_request="",
            rate_samples=(),
            temp_samples=(),
            device=None,
            jog=None,
        )
        if self.state.file.path != path:
            self.open_file(path)
        self.say(
            ConsoleLine(
                "notice", f"following the print already running: {path}", self.app.wall_clock()
            )
        )
        self._run_job(job_id, sink, lambda: job)
        return True

    def start(
        self,
        resume_from_layer: int | None = None,
        exact: ResumeView | None = None,
        clear_fault: bool = False,
    ) -> None:
        """Start the open file (``resume_from_layer``: 0-based layer to restart at; ``exact``:
        continue at that saved resume point, ``print --resume``; ``clear_fault``: the operator
        was shown the device's fault and accepted that the start clears it)."""
        path = self.state.file.path
        if not path or self.state.job_active:
            return
        job_id = self.state.job_id + 1
        self._status_gen += 1  # a status asked before now is old news
        self.update(
            # the job is under way from now (its first event, preflight, comes from a worker):
            # until then no status poll may show the device as it was before the print
            job=JobSnapshot(state=JobState.PREFLIGHT),
            job_id=job_id,
            job_path=path,
            job_started=self.app.wall_clock(),
            job_ended=0.0,
            notice_at=None,
            job_resumed_from=exact.layer
            if exact is not None
            else None
            if resume_from_layer is None
            else resume_from_layer + 1,
            job_resume_line=exact.last_line if exact is not None else None,
            job_request="",
            rate_samples=(),
            temp_samples=(),
            device=None,
            jog=None,
        )
        what = "print"
        if exact is not None:
            what = f"resume at line {exact.last_line} (layer {exact.layer})"
        elif resume_from_layer is not None:
            what = f"resume at layer {resume_from_layer + 1}"
        self.say(ConsoleLine("notice", f"{what}: {path}", self.app.wall_clock()))
        sink = self.app.pump.sink(job_id)
        self._run_job(
            job_id,
            sink,
            lambda: self.backend.make_job(
                path, sink, resume_from_layer, exact is not None, clear_fault
            ),
        )

    def _run_job(self, job_id: int, sink: Any, make: Any) -> None:
        """Run the job ``make`` returns in a worker, to its end."""
        ended = self._job_ended = threading.Event()

        def work() -> Any:
            try:
                job = make()
                with self._job_lock:
                    self._job = job
                return job.run()
            finally:
                with self._job_lock:
                    self._job = None
                ended.set()

        def done(result: Any) -> None:
            self.finished(job_id, None)

        def fail(exc: BaseException) -> None:
            if not self.state.job.state.finished:  # the runner died without saying so
                sink(StateChanged(JobState.FAILED, str(exc) or type(exc).__name__))
            self.finished(job_id, exc)

        self.background("job", work, done, fail)

    def finished(self, job_id: int, error: BaseException | None) -> None:
        """The runner returned (or raised); its last events may still be in the pump. Once per
        job: the history record (with the resume point saved), then a look at the link, or
        (quitting) the exit."""
        self.app.drain_events()
        if job_id != self.state.job_id or self._finished_id == job_id:
            return
        self._finished_id = job_id
        self._status_gen += 1  # (a status asked while it ran answers only now: old news)
        state = self.state
        if error is not None:
            self.app.notify(
                str(error) or type(error).__name__, title="print", severity="error", timeout=10
            )
        elif state.job.state is JobState.DONE:
            self.app.notify("print finished", title="print")
        if state.job_path and (state.job.state.finished or self._quitting):
            self._record(job_record(state, self.app.wall_clock()))
        if self._quitting:  # the job has ended and is recorded: now the link closes
            _quiet(self.backend.close)
            self.app.exit(0)
            return
        self.probe_connection()

    def _record(self, record: JobRecord) -> None:
        """Into the history: at once on the screen; the resume point (read from its file) and
        the line in the history file from a worker, or here when quitting (the app exits)."""
        backend, history = self.backend, self.app.job_history

        def work() -> JobRecord:
            full = record
            if record.status != "done":
                resume = _quiet(lambda: backend.find_resume(record.file))
                if resume is not None and not resume.problem:
                    at = f"line {resume.last_line} " if resume.exact else ""
                    full = replace(record, resume_at=f"{at}(layer {resume.layer})".strip())
            history.append(full)
            return full

        def done(full: JobRecord) -> None:
            self.update(history=tuple(full if r is record else r for r in self.state.history))

        self.update(history=(record, *self.state.history)[:HISTORY_MAX])  # the file keeps all
        if self._quitting:
            done(work())
        else:
            self.background("history", work, done, lambda _: None)

    # -------------------------------------------------------------- quitting
    @property
    def quitting(self) -> str:
        return self._quitting

    def stop_and_quit(self, reason: str = "quit") -> None:
        """Quit safely: a running job is stopped like a cancel (``reason`` recorded: "quit",
        "SIGTERM" ...) and waited for; then its record, then the exit (the link is closed
        after that, on unmount). Asked twice: an emergency stop, then the exit."""
        with self._job_lock:
            job = self._job
        if self._quitting:
            self.emergency_stop()
            return
        if job is None:
            self.app.exit(0)
            return
        self._quitting = reason
        job_id, ended = self.state.job_id, self._job_ended
        self.update(job_request="cancel")
        self.say(
            ConsoleLine("notice", f"{reason}: stopping the print first", self.app.wall_clock())
        )
        self.app.notify(
            "stopping the machine before quitting (stop, park, heaters off); the app closes when "
            "it is at rest",
            title=reason,
            timeout=SHUTDOWN_TIMEOUT_S + 5,
        )

        def work() -> bool:
            return shutdown_job(job, ended, reason, SHUTDOWN_TIMEOUT_S)

        def done(stopped: bool) -> None:
            if not stopped:
                self.say(
                    ConsoleLine("error", "the job did not stop in time", self.app.wall_clock())
                )
            self.finished(job_id, None)

        self.background("quit", work, done, lambda exc: self.finished(job_id, exc))

    def stop_before_close(self) -> None:
        """Blocking, on unmount: a job still running (the app left without the quit path) is
        stopped before the link closes."""
        with self._job_lock:
            job = self._job
        if job is not None:
            _quiet(lambda: shutdown_job(job, self._job_ended, "quit", SHUTDOWN_TIMEOUT_S))

    def probe_connection(self) -> None:
        """After a job: is the link alive? (A job may have re-opened it, or lost it.) The
        device is read again (temperatures, position: the job parked it after a cancel)."""
        self.recheck_link(self.lookup_resume)

    def _request(self, what: str) -> bool:
        with self._job_lock:
            job = self._job
        if job is None:
            return False
        getattr(job, f"request_{what}")()
        return True

    def pause(self) -> None:
        if self.state.job.state in (JobState.PRINTING, JobState.HEATING) and self._request("pause"):
            self.update(job_request="pause")

    def resume(self) -> None:
        if self._request("resume"):
            self.update(job_request="")

    def cancel(self) -> None:
        if self.state.job.state.active and self._request("cancel"):
            self.update(job_request="cancel")

    # ------------------------------------------------------------------ resume
    def resume_failed(self) -> None:
        """Resume the open file's failed print at its saved point (exact, like ``--resume``,
        when it names a move; else at its layer), with the CLI's checks: the
        resume point belongs to this file and is usable, the link answers, the operator
        confirms that the part is on the bed and clear. Nothing starts when a check fails."""
        path = self.state.file.path
        if not path or self.state.job_active:
            return
        if not self.state.connected:
            self.app.notify(
                f"not connected: reconnect on {screen_key('connection')} first; nothing started",
                severity="warning",
            )
            return
        backend = self.backend

        def work() -> tuple[DeviceStatusView | None, ResumeView | None]:
            return backend.device_status(), backend.find_resume(path)  # raises: link dead

        def done(found: tuple[DeviceStatusView | None, ResumeView | None]) -> None:
            status, resume = found
            if status is not None:
                self.device_seen(status)
            fault = status.fault if status is not None else ""
            self.update(file=replace(self.state.file, resume=resume))
            if fault and status is not None and not status.fault_clearable:
                self.app.notify(f"cannot resume: {fault}", severity="error", timeout=10)
                return
            if resume is None:
                self.app.notify(
                    f"no resume point saved for {Path(path).name}", severity="warning", markup=False
                )
                return
            if resume.problem:
                self.app.notify(f"cannot resume: {resume.problem}", severity="error", timeout=10)
                return
            question = resume.question or resume_question(Path(path).name, layer=resume.layer)
            if fault:  # clearing it is the operator's decision
                question = f"{fault[0].upper()}{fault[1:]}; resuming clears it. {question}"
            clear = bool(fault)
            if resume.exact:  # print --resume: exactly where it stopped
                self.app.confirm(question, lambda: self.start(exact=resume, clear_fault=clear))
            else:
                layer = resume.layer - 1
                self.app.confirm(
                    question, lambda: self.start(resume_from_layer=layer, clear_fault=clear)
                )

        def fail(exc: BaseException) -> None:
            text = str(exc) or type(exc).__name__
            conn = self.state.connection
            self.update(connection=replace(conn, status="error", error=text))
            self.app.notify(
                f"the link does not answer ({text}): reconnect on {screen_key('connection')}; "
                "nothing started, the resume point is kept",
                severity="error",
                timeout=10,
            )

        self.background("resume-check", work, done, fail, exclusive=True)
