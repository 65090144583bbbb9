"""The web page of the print server: the page and its assets, the event stream, its routes.

- :class:`WebFront` (ASGI, in front of the key gate) answers ``GET /`` and the page's few
  assets from ``cdprhost/server/static`` (hand-written HTML, CSS and JS shipped in the
  package: no CDN, no build step). They hold nothing of the printer, so they need no key;
  everything else goes through the key gate unchanged.
- :func:`add_routes` adds the page's routes to the API (all behind the key):
  ``GET /api/web/events`` (server-sent events: the state document of
  :mod:`cdprhost.server.web_state`, pushed at once on a state change and at most every
  ``THROTTLE_S`` otherwise), ``GET /api/web/layer?n=K`` (one layer of the job's toolpath),
  ``POST /api/web/start`` (print a stored file), ``POST /api/web/control`` (e-stop, heaters
  off, home, jog: :mod:`cdprhost.server.web_controls`), ``GET /api/web/camera``.
- :class:`Hub`: one sampler for every browser watching (the document is built and encoded
  once per change, not once per browser); it runs only while a browser is connected.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, Response, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.concurrency import run_in_threadpool

from cdprhost.errors import CdprError
from cdprhost.job.state import Temperatures
from cdprhost.server import web_state
from cdprhost.server.guard import ASGIApp, Receive, Scope, Send
from cdprhost.server.printer import Printer, PrinterStatus, Refused
from cdprhost.server.uploads import BadName, NotGcode
from cdprhost.server.web_controls import Control, act
from cdprhost.server.web_layers import LayerCache

log = logging.getLogger(__name__)

STATIC = Path(__file__).parent / "static"
#: the page's files: URL path -> (file in STATIC, content type); nothing else is served
ASSETS = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/static/app.css": ("app.css", "text/css; charset=utf-8"),
    "/static/app.js": ("app.js", "text/javascript; charset=utf-8"),
    "/static/icon.svg": ("icon.svg", "image/svg+xml"),
}
CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'"
)
SAMPLE_S = 0.1  # how often the hub looks at the printer while a browser watches
THROTTLE_S = 0.5  # at most one update per this, except a state change (sent at once)
KEEPALIVE_S = 15.0
HISTORY = 20
IDLE_SAMPLE_S = 0.5  # ... while no browser watches (the history still sees each job end)
IDLE_TEMPS_S = 1.0  # with no job, the heaters are asked of the printer this often while watched
PRIVATE = ("key", "resume_of")  # history fields the page is not sent


class WebFront:
    """The page and its assets (public, no printer data), else the keyed application."""

    def __init__(self, app: ASGIApp, static: Path = STATIC):
        self.app = app
        self.files: dict[str, tuple[bytes, bytes, bytes]] = {}
        for route, (name, kind) in ASSETS.items():
            body = (static / name).read_bytes()
            etag = f'"{hashlib.sha256(body).hexdigest()[:16]}"'.encode()
            self.files[route] = (body, kind.encode(), etag)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        asset = self.files.get(scope.get("path", "")) if scope["type"] == "http" else None
        if asset is None or scope.get("method") not in ("GET", "HEAD"):
            await self.app(scope, receive, send)
            return
        body, kind, etag = asset
        headers = [
            (b"content-type", kind),
            (b"etag", etag),
            (b"cache-control", b"no-cache"),
            (b"content-security-policy", CSP.encode()),
            (b"x-content-type-options", b"nosniff"),
            (b"x-frame-options", b"DENY"),
            (b"referrer-policy", b"no-referrer"),
        ]
        inm = dict(scope.get("headers", ())).get(b"if-none-match")
        if inm == etag:
            await send({"type": "http.response.start", "status": 304, "headers": headers})
            await send({"type": "http.response.body", "body": b""})
            return
        headers.append((b"content-length", str(len(body)).encode()))
        await send({"type": "http.response.start", "status": 200, "headers": headers})
        await send(
            {"type": "http.response.body", "body": b"" if scope["method"] == "HEAD" else body}
        )


class Hub:
    """The state document, sampled once for every browser watching, and the job history."""

    def __init__(
        self,
        printer: Printer,
        relative: Callable[[Path | None], str | None],
        camera: bool = False,
    ):
        self.printer = printer
        self.relative = relative
        profile = getattr(printer, "profile", None)
        self.bed_origin = tuple(profile.build_volume.bed_origin) if profile is not None else None
        self.camera = camera
        self.history: deque[dict[str, Any]] = deque(maxlen=HISTORY)
        self.doc: dict[str, Any] | None = None
        self.data = b""
        self.version = 0
        self.clients = 0
        self._status: PrinterStatus | None = None
        self.idle_temps: Temperatures | None = None  # asked of the printer with no job running
        self._temps: Temperatures | None = None  # ... as the published document has them
        self._temps_at = -IDLE_TEMPS_S
        self._published_at = 0.0
        self._pending = False
        self._changed: asyncio.Event | None = None
        self._task: asyncio.Task[None] | None = None

    # ------------------------------------------------------------ sampling
    def sample(self, now: float) -> bool:
        """Look at the printer once; True when a new document was published."""
        status = self.printer.status()
        temps = None if status.busy else self.idle_temps
        if (status is not self._status and status != self._status) or temps != self._temps:
            self._status = status
            self._temps = temps
            doc = web_state.view(
                status, self.relative(status.file), self.bed_origin, idle_temps=temps
            )
            urgent = web_state.urgent(self.doc, doc)
            self._record(self.doc, doc)
            self.doc = doc
            if urgent or now - self._published_at >= THROTTLE_S:
                self._publish(now)
                return True
            self._pending = True
        if self._pending and now - self._published_at >= THROTTLE_S:
            self._publish(now)
            return True
        return False

    def _record(self, before: dict[str, Any] | None, after: dict[str, Any]) -> None:
        record = web_state.finished_record(after)
        if record is None:
            return
        if (
            before is not None
            and before["state"] == after["state"]
            and before["file"] == after["file"]
        ):
            return
        if self.history and self.history[0].get("key") == (after["file"], after["elapsed_s"]):
            return
        entry = {**record, "key": (after["file"], after["elapsed_s"]), "resume": None}
        if self._status is not None and self._status.file is not None:
            entry["resume_of"] = self._status.file
        self.history.appendleft(entry)

    def _publish(self, now: float) -> None:
        assert self.doc is not None
        history = [{k: v for k, v in h.items() if k not in PRIVATE} for h in self.history]
        doc = {**self.doc, "history": history, "camera": self.camera, "now": round(time.time(), 1)}
        self.version += 1
        self.data = (
            b"event: state\ndata: " + json.dumps(doc, separators=(",", ":")).encode() + b"\n\n"
        )
        self._published_at = now
        self._pending = False
        if self._changed is not None:
            self._changed.set()
            self._changed = asyncio.Event()

    async def _run(self) -> None:
        """From the first browser on: often while one watches, seldom otherwise (the history
        keeps the jobs that end while nobody watches)."""
        failing = False
        try:
            while True:
                try:
                    if self.clients > 0:
                        await asyncio.to_thread(self.poll_temperatures, time.monotonic())
                    self.sample(time.monotonic())
                    await self._find_resume_points()
                    failing = False
                except Exception:  # a printer that fails to answer: said once, sampled again
                    if not failing:
                        log.exception("the web page's state could not be read")
                    failing = True
                await asyncio.sleep(SAMPLE_S if self.clients > 0 else IDLE_SAMPLE_S)
        finally:
            self._task = None

    def poll_temperatures(self, now: float) -> None:
        """Blocking: with no job running, the printer's heaters (at most every IDLE_TEMPS_S),
        so a page watches the nozzle cool after a print or a fault."""
        if now - self._temps_at < IDLE_TEMPS_S or self.printer.status().busy:
            return
        self._temps_at = now
        try:
            reading = self.printer.temperatures()
        except Refused:
            reading = None
        if reading is not None:
            self.idle_temps = reading

    async def _find_resume_points(self) -> None:
        """The resume point each ended job saved (read in a worker thread: hashing the file)."""
        for record in list(self.history):
            if "resume_of" not in record:
                continue
            path = record.pop("resume_of")
            record["resume"] = await asyncio.to_thread(self.resume_point, path)
            self._pending = True

    def resume_point(self, path: Path) -> str | None:
        """Blocking: "line N (layer L)" of the point saved for ``path``, or None."""
        from cdprhost.job.resume import find_resume_point

        folder = (getattr(self.printer, "job_options", None) or {}).get("resume_dir")
        try:
            point = find_resume_point(path, folder)
        except (OSError, ValueError, CdprError):
            return None
        if point is None:
            return None
        return f"line {point.last_line} (layer {point.last_layer})"

    # ------------------------------------------------------------- clients
    async def stream(self) -> AsyncIterator[bytes]:
        """One browser's events: the current document at once, then each new one."""
        if self._changed is None:
            self._changed = asyncio.Event()
        self.clients += 1
        if self._task is None:
            self.sample(time.monotonic())
            self._task = asyncio.create_task(self._run())
        try:
            yield b"retry: 2000\n\n"
            seen = 0
            while True:
                if self.version != seen:
                    seen = self.version
                    yield self.data
                    continue
                changed = self._changed
                try:
                    await asyncio.wait_for(changed.wait(), KEEPALIVE_S)
                except TimeoutError:
                    yield b": keepalive\n\n"
        finally:
            self.clients -= 1


class StartFile(BaseModel):
    """``POST /api/web/start``: a stored file (its path in the upload folder)."""

    model_config = ConfigDict(extra="forbid")
    path: str = Field(min_length=1, max_length=2000)


def _refused(status: int, text: str) -> JSONResponse:
    return JSONResponse({"error": text}, status_code=status)


def _invalid(what: str, exc: Exception) -> JSONResponse:
    if isinstance(exc, ValidationError):
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "body"
        return _refused(400, f"{what}: {where}: {err['msg']}")
    return _refused(400, f"{what}: the body is not JSON")


def add_routes(
    app: FastAPI, api: Any, camera: Callable[[], tuple[bytes, str]] | None = None
) -> Hub:
    """The page's routes on ``app`` (behind the key gate); ``api``: :class:`~.app.Api`;
    ``camera``: a snapshot source (e.g. :class:`~.web_camera.CameraSnapshot`), or None."""
    printer: Printer = api.printer
    hub = Hub(printer, api.relative, camera is not None)
    profile = getattr(printer, "profile", None)

    def read_items(path: Path) -> Any:
        from cdprhost.motion.prepared import Setup, prepare

        assert profile is not None  # the route refuses first without one
        model = getattr(printer, "model", None)
        setup = getattr(printer, "setup", None) or Setup()
        return prepare(path, profile, model, setup).items()

    layers = LayerCache(read_items)

    @app.get("/api/web/events")
    async def events() -> StreamingResponse:
        return StreamingResponse(
            hub.stream(),
            media_type="text/event-stream",
            headers={"cache-control": "no-store", "x-accel-buffering": "no"},
        )

    @app.get("/api/web/layer")
    async def layer(n: int = 0) -> Response:
        path = printer.status().file
        if path is None:
            return _refused(404, "no job: no layer to show")
        if profile is None:
            return _refused(404, "the layer view is not offered here")
        try:
            doc = await run_in_threadpool(layers.layer, path, n)
        except OSError as exc:
            return _refused(404, f"{path.name}: {exc.strerror or exc}")
        except (CdprError, ValueError) as exc:  # a file that does not read: said, nothing else
            log.warning("layer view of %s: %s", path.name, exc)
            return _refused(422, f"{path.name}: {exc}")
        return JSONResponse(doc)

    @app.post("/api/web/start")
    async def start(request: Request) -> Response:
        try:
            body = StartFile.model_validate(await request.json())
        except (ValidationError, ValueError) as exc:
            return _invalid("start", exc)
        try:
            path = api.uploads.find(body.path)
        except (BadName, NotGcode) as exc:
            return _refused(400, str(exc))
        if path is None:
            return _refused(404, f"{body.path}: no such file")
        from cdprhost.server.client_name import client_name

        try:
            async with api.lock:
                await run_in_threadpool(printer.check_start, path)
                await run_in_threadpool(printer.start, path, client_name(request))
        except Refused as exc:
            return _refused(409, str(exc))
        api.selected = path
        return JSONResponse({"started": api.relative(path)}, status_code=202)

    @app.post("/api/web/control")
    async def control(request: Request) -> Response:
        try:
            body = Control.model_validate(await request.json())
        except (ValidationError, ValueError) as exc:
            return _invalid("control", exc)
        try:
            done = await run_in_threadpool(act, printer, body)
        except Refused as exc:
            return _refused(409, str(exc))
        return JSONResponse({"done": done})

    @app.get("/api/web/camera")
    async def camera_snapshot() -> Response:
        if camera is None:
            return _refused(404, "no camera is configured (serve --camera)")
        try:
            image, kind = await run_in_threadpool(camera)
        except (CdprError, OSError, RuntimeError, ValueError) as exc:  # said; nothing else touched
            return _refused(503, f"the camera did not answer: {exc}")
        return Response(image, media_type=kind, headers={"cache-control": "no-store"})

    with contextlib.suppress(AttributeError):
        api.hub = hub
    return hub
