"""The printer service: the job, the link and the device state in one process; front ends
are its clients.

One service owns one device (or one embedded simulated device). It listens on a Unix
socket of mode 0600 in a private folder and refuses every client that does not present
its key. Each client gets its own bounded outgoing queue and sender thread: a client that
stops reading (a hung or stopped front end) loses its connection when its queue is full,
and a client that goes away never touches the job. The job's events are kept compacted
(:mod:`cdprhost.service.journal`), so a front end that attaches later sees the same state.
Between prints a front end may hold the device (:mod:`cdprhost.service.device_session`):
one link, the machine operations the TUI needs, the status broadcast to every client.
The service exits once no job runs and no client has been connected for ``idle_s``.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.job.state import Event, JobState
from cdprhost.logs import attach_log_file, detach_log_file
from cdprhost.service import wire
from cdprhost.service.clients import Client
from cdprhost.service.device_session import DeviceSession, Opener
from cdprhost.service.journal import Journal
from cdprhost.service.paths import ServiceFiles, device_name, key_matches, write_key

log = logging.getLogger(__name__)

#: how long a new service waits for the front end that started it
FIRST_CLIENT_S = 60.0


class ServiceBusy(RuntimeError):
    """Another service already owns this device (its lock is held)."""


class _Forward(logging.Handler):
    """Warnings of the job's modules, to every client (they show them as the CLI did)."""

    def __init__(self, service: PrinterService):
        super().__init__(logging.WARNING)
        self.service = service

    def emit(self, record: logging.LogRecord) -> None:
        if record.name.startswith("cdprhost.service"):
            return  # the service's own affairs (a dropped client) are not the job's
        text = f"{record.name}: {record.getMessage()}"
        self.service.broadcast(wire.LogMsg(level=record.levelname, text=text))


class PrinterService:
    def __init__(
        self,
        files: ServiceFiles,
        port: str | None,
        *,
        idle_s: float = 30.0,
        link_factory: Callable[[wire.StartJob, Any], Callable[[], Any]] | None = None,
        device_opener: Opener | None = None,
    ):
        self.files = files
        self.port = port
        self.idle_s = idle_s
        self.link_factory = link_factory or default_link_factory
        self._lock = threading.RLock()
        self._clients: set[Client] = set()
        self._count = 0
        self._journal = Journal()
        self._job: PrintJob | None = None
        self._job_thread: threading.Thread | None = None
        self._result: wire.ResultMsg | None = None
        self._idle_since = time.monotonic()
        self._stop = threading.Event()
        self._key = ""
        self._lockfile: Any = None
        self._listener: socket.socket | None = None
        self._forward: logging.Handler | None = None
        self._job_info: wire.JobInfo | None = None  # the current or last job's file and starter
        self.session = DeviceSession(
            port,
            self.broadcast,
            lambda: self.job_running,
            opener=device_opener,
            job_link=lambda: self._job.link if self._job is not None else None,
        )

    # ------------------------------------------------------------ lifetime
    def bind(self) -> None:
        """Take the device's lock, write the key and listen (ServiceBusy when another
        service owns the device)."""
        old = os.umask(0o077)
        try:
            fh = open(self.files.lock, "a")  # noqa: SIM115 - held for the service's life
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.close()
                raise ServiceBusy(str(self.files.socket)) from None
            self._lockfile = fh
            self._key = write_key(self.files.key)
            with contextlib.suppress(FileNotFoundError):
                self.files.socket.unlink()
            listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            listener.bind(str(self.files.socket))
            os.chmod(self.files.socket, 0o600)
            listener.listen(16)
            listener.settimeout(0.25)
            self._listener = listener
            self.files.pid.write_text(f"{os.getpid()}\n")
        finally:
            os.umask(old)
        self._forward = _Forward(self)
        logging.getLogger("cdprhost").addHandler(self._forward)

    def serve(self) -> None:
        """Accept clients until idle (no job, no client for ``idle_s``) or stopped."""
        assert self._listener is not None
        try:
            while not self._stop.is_set():
                try:
                    conn, _ = self._listener.accept()
                except TimeoutError:
                    if self._idle():
                        break
                    continue
                with self._lock:
                    self._count += 1
                    client = Client(conn, self, self._count)
                client.start()
        finally:
            self.close()

    def _idle(self) -> bool:
        with self._lock:
            if self._clients or self.job_running:
                self._idle_since = time.monotonic()
                return False
            wait = self.idle_s if self._count else max(self.idle_s, FIRST_CLIENT_S)
            return time.monotonic() - self._idle_since >= wait

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        """Stop listening, remove the socket, key and pid (only while still ours)."""
        if self._forward is not None:
            logging.getLogger("cdprhost").removeHandler(self._forward)
            self._forward = None
        if self._listener is not None:
            with contextlib.suppress(OSError):
                self._listener.close()
            self._listener = None
            for path in (self.files.socket, self.files.key, self.files.pid):
                with contextlib.suppress(OSError):
                    path.unlink()
        with self._lock:
            clients = list(self._clients)
        for client in clients:
            client.close()
        self.session.close()
        if self._lockfile is not None:
            self._lockfile.close()
            self._lockfile = None

    def shutdown_job(self, reason: str) -> None:
        """A signal to the service: cancel like the operator (stop, park, heaters off)."""
        job = self._job
        if job is not None and not job.finished:
            job.shutdown(reason)
        thread = self._job_thread
        if thread is not None:
            thread.join(30.0)
        self.stop()

    @property
    def job_running(self) -> bool:
        thread = self._job_thread
        return thread is not None and thread.is_alive()

    # ------------------------------------------------------------ clients
    def admit(self, client: Client, hello: wire.Hello) -> bool:
        if hello.v != wire.VERSION:
            client.send(
                wire.Reply(
                    ok=False, error=f"wire version {hello.v}; this service speaks {wire.VERSION}"
                )
            )
            return False
        if not key_matches(hello.key, self._key):
            client.send(wire.Reply(ok=False, error="refused: wrong or missing key"))
            return False
        client.who = hello.client or "?"
        with self._lock:
            job = self._job
            state = job.state.value if job is not None else "none"
            client.send(
                wire.Welcome(
                    v=wire.VERSION, pid=os.getpid(), name=self.files.name, port=self.port, job=state
                )
            )
            if hello.replay:
                if self._job_info is not None:
                    client.send(self._job_info.model_copy(update={"state": state}))
                for event in self._journal.replay():
                    client.send(wire.EventMsg(event=wire.event_to_json(event)))
                if self._result is not None:
                    client.send(self._result)
            self._clients.add(client)
        log.info("client %d (%s) attached", client.number, client.who)
        return True

    def forget(self, client: Client) -> None:
        with self._lock:
            self.session.release(client.number)
            if client in self._clients:
                self._clients.discard(client)
                self._idle_since = time.monotonic()
                log.info("client %d (%s) left", client.number, client.who)

    def broadcast(self, message: BaseModel) -> None:
        line = wire.encode(message)  # once, whoever listens
        with self._lock:
            clients = list(self._clients)
        for client in clients:
            client.send(line)

    def handle(self, client: Client, request: Any) -> None:
        if isinstance(request, wire.DeviceRequest):
            self._device(client, request)
            return
        if isinstance(request, wire.Estop) and not self.job_running and self.session.open:
            client.send(self.session.emergency_stop(request.id))
            return
        if isinstance(request, wire.Start):
            error = self._start(client, request)
            if error:
                client.send(wire.Reply(id=request.id, ok=False, error=error))
            return
        job = self._job
        if job is None or job.finished:
            client.send(wire.Reply(id=request.id, ok=False, error="no print is running"))
            return
        if isinstance(request, wire.Pause):
            job.request_pause()
        elif isinstance(request, wire.Resume):
            job.request_resume()
        elif isinstance(request, wire.Cancel):
            job.request_cancel(request.reason)
        elif isinstance(request, wire.Estop):
            threading.Thread(target=job.emergency_stop, name="estop", daemon=True).start()
            if job.link is None and self.session.open:
                # a job in its preflight holds no link yet: the device session's link
                # stops the device now (motors kept, heaters off), as with no job
                self.session.emergency_stop(request.id)
        elif isinstance(request, wire.Override):
            try:
                getattr(job, f"request_{request.what}")(request.percent)
            except ValueError as exc:
                client.send(wire.Reply(id=request.id, ok=False, error=str(exc)))
                return
        client.send(wire.Reply(id=request.id, ok=True))

    def _device(self, client: Client, request: Any) -> None:
        """A device-session request, in a thread of its own (a homing takes seconds; the
        client's next line, an e-stop, is read meanwhile)."""

        def work() -> None:
            try:
                if isinstance(request, wire.Connect):
                    answer = self.session.connect(client.number, request)
                elif isinstance(request, wire.Disconnect):
                    self.session.release(client.number)
                    answer = wire.Answer(id=request.id, ok=True)
                else:
                    answer = self.session.run(request)
            except Exception as exc:  # a bug: the client is answered, the service lives
                log.exception("the device request %s broke", request.op)
                answer = wire.Answer(id=request.id, ok=False, error=f"internal error: {exc}")
            client.send(answer)

        threading.Thread(target=work, name=f"device-{request.op}", daemon=True).start()

    # ------------------------------------------------------------ the job
    def _start(self, client: Client, request: wire.Start) -> str:
        from cdprhost.job.resume import find_resume_point
        from cdprhost.motion.prepared import Setup
        from cdprhost.profile.models import MachineProfile

        spec = request.job
        mine = self.port is None if spec.port is None else device_name(spec.port) == self.files.name
        if not mine:
            return f"this service drives {self.port or 'the embedded device'}, not {spec.port}"
        try:
            profile = MachineProfile.model_validate(spec.profile)
            setup = Setup.from_json(spec.setup)
        except (ValidationError, ValueError) as exc:
            return f"refused: start: {exc}"
        point = None
        if spec.resume:
            point = find_resume_point(spec.gcode)
            if point is None or not point.exact:
                return f"{spec.gcode}: no resume point to continue at"
        options = PrintOptions(
            setup=setup,
            resume_from_layer=spec.resume_from_layer,
            resume=point,
            log_path=spec.log_path,
            clear_fault=spec.clear_fault,
        )
        if spec.port is not None and spec.profile_ref is not None:
            from cdprhost.profile import record_device

            options.record_device = functools.partial(record_device, spec.profile_ref)
        with self._lock:
            if self.job_running:
                job = self._job
                name = job.gcode.name if job is not None else "?"
                state = job.state.value if job is not None else "?"
                watch = f"--attach --port {self.port}" if self.port else "--attach --port PORT"
                return (
                    f"a print is running on {self.port or 'this device'} ({name}, {state}); "
                    f"`cdprhost print {watch}` watches it"
                )
            self._journal = Journal()
            self._result = None
            opener = (
                self.session.link_for_job if self.session.open else self.link_factory(spec, profile)
            )
            job = PrintJob(
                spec.gcode,
                profile,
                opener,
                options,
                on_event=self._on_event,
            )
            self._job = job
            self._job_info = wire.JobInfo(
                gcode=spec.gcode,
                state="idle",
                started_by=spec.started_by or client.who,
                started_at=time.time(),
            )
            info = wire.encode(self._job_info)
            for other in list(self._clients):  # before the job's first event
                other.send(info)
            client.send(wire.Reply(id=request.id, ok=True))
            thread = threading.Thread(target=self._run_job, args=(job, spec), name="print-job")
            self._job_thread = thread
            thread.start()
        return ""

    def _on_event(self, event: Event) -> None:
        """The job thread's only call into the service: record, queue, return."""
        line = wire.encode(wire.EventMsg(event=wire.event_to_json(event)))
        with self._lock:  # queue puts only: the order every client sees is the journal's
            self._journal.add(event)
            for client in list(self._clients):
                client.send(line)

    def _run_job(self, job: PrintJob, spec: wire.StartJob) -> None:
        handler = None
        if spec.job_log_file:
            with contextlib.suppress(OSError):
                Path(spec.log_path).parent.mkdir(parents=True, exist_ok=True)
            handler = attach_log_file(Path(spec.log_path).with_suffix(".log"), quiet=True)
        try:
            result = job.run()
            message = wire.ResultMsg(result={**result.to_json(), "bad_input": result.bad_input})
        except Exception as exc:  # a bug: every client is told, the service lives
            log.exception("the print job broke")
            message = wire.ResultMsg(error=f"internal error: {type(exc).__name__}: {exc}")
        finally:
            link = job.link
            if link is not None and not self.session.holds(link):
                with contextlib.suppress(Exception):
                    link.close()
            detach_log_file(handler)
        with self._lock:
            self._result = message
            self._idle_since = time.monotonic()
            clients = list(self._clients)
        for client in clients:
            client.send(message)
        self.session.after_job()
        if job.state is JobState.IDLE:
            log.info("the job ended before it began")


def default_link_factory(spec: wire.StartJob, profile: Any) -> Callable[[], Any]:
    if spec.port:
        from cdprhost.link import open_link

        baud = spec.baud or profile.serial.baud
        port = spec.port
        return lambda: open_link(port, baud=baud, timeout_s=profile.serial.timeout_s)
    from cdprhost.sim.embedded import open_embedded

    return lambda: open_embedded(speedup=spec.speedup, faults=spec.sim_faults)


def install_signals(service: PrinterService) -> None:
    """SIGTERM, SIGINT, SIGHUP to the service: the job is cancelled like the operator would
    (stop, park, heaters off, resume point), then the service exits."""

    def handler(signum: int, frame: Any) -> None:
        name = signal.Signals(signum).name
        threading.Thread(target=service.shutdown_job, args=(name,), daemon=True).start()

    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, handler)
