"""The slicer upload API: the part of OctoPrint's REST API that slicers and phone apps use.

Framework: FastAPI (on Starlette, served by uvicorn). Chosen for the long run because it
validates requests with the pydantic models the rest of cdprhost already uses at its
boundaries (one way of saying "bad input, named"), it is plain ASGI (the gate in
:mod:`cdprhost.server.guard` is a framework-free middleware, and the server can be swapped for
any ASGI server), and it runs in a thread beside the terminal UI's own event loop without
sharing it. aiohttp would have served too (one package, its own streaming multipart reader),
but it brings a second validation style and its server is tied to its framework.

Routes (every one behind the API key, see :mod:`cdprhost.server.guard`):
``GET /api/version``, ``GET /api/server``, ``GET /api/job``, ``POST /api/job``,
``GET /api/printer``, ``GET /api/settings``,
``GET /api/files``, ``GET /api/files/local``, ``GET /api/files/local/{path}``,
``POST /api/files/local``.
"""

from __future__ import annotations

import asyncio
import logging
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict, ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.requests import ClientDisconnect

from cdprhost.server import shapes
from cdprhost.server.client_name import client_name
from cdprhost.server.filepos import FilePosition
from cdprhost.server.guard import BodyTooLarge, KeyGuard
from cdprhost.server.hosts import HostNames
from cdprhost.server.printer import Printer, Refused, busy_reason
from cdprhost.server.uploads import (
    BadName,
    Entry,
    NotGcode,
    UnsafeStaging,
    UploadFolder,
    check_filename,
    check_folder,
)
from cdprhost.server.web import WebFront, add_routes

log = logging.getLogger(__name__)

TRUE = ("true", "yes", "y", "1", "on")
FALSE = ("false", "no", "n", "0", "off", "")
MAX_FIELDS = 16
COPY_CHUNK = 1 << 20


class JobCommand(BaseModel):
    """``POST /api/job``: OctoPrint's job commands (``restart`` is refused: no SD-style
    restart here; start a file again instead)."""

    model_config = ConfigDict(extra="ignore")
    command: Literal["start", "cancel", "pause"]
    action: Literal["pause", "resume", "toggle"] = "toggle"


def error(status: int, text: str) -> JSONResponse:
    return JSONResponse({"error": text}, status_code=status)


def flag(value: Any, name: str) -> bool:
    if value is None:
        return False
    if isinstance(value, UploadFile):
        raise BadName(f"{name}: a form field, not a file")
    text = str(value).strip().lower()
    if text in TRUE:
        return True
    if text in FALSE:
        return False
    raise BadName(f"{name}: {str(value)[:40]!r} is not true or false")


class Api:
    """The routes' state: the printer, the upload folder, the selected file."""

    def __init__(self, printer: Printer, uploads: UploadFolder):
        self.printer = printer
        self.uploads = uploads
        self.selected: Path | None = None
        self.filepos = FilePosition()
        self.lock = asyncio.Lock()  # one upload-and-start decision at a time

    def relative(self, path: Path | None) -> str | None:
        if path is None:
            return None
        try:
            return self.uploads.relative(path)
        except ValueError:
            return path.name

    def store(self, upload: UploadFile, folder: tuple[str, ...], name: str, start: bool) -> Path:
        """Blocking: write the upload to staging, check it (when it is to print), move it in.
        Raises Refused (409) with nothing written when it may not print."""
        target = self.uploads.target(folder, name)
        status = self.printer.status()
        if status.busy and status.file is not None and _same(status.file, target):
            raise Refused(f"{name} is printing now: upload it under another name")
        if start and status.busy:
            raise Refused(busy_reason(status))
        try:
            staged = self.uploads.stage(name)
        except UnsafeStaging as exc:
            log.warning("upload refused: %s", exc)
            raise Refused(f"{exc}; nothing stored") from None
        try:
            with open(staged, "wb") as out:
                shutil.copyfileobj(upload.file, out, COPY_CHUNK)
            if start:
                try:
                    self.printer.check_start(staged)
                except Refused as exc:
                    rel = "/".join((*folder, name))
                    raise Refused(str(exc).replace(str(staged), rel)) from None
            return self.uploads.commit(staged, target)
        finally:
            self.uploads.discard(staged)


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def create_app(
    printer: Printer,
    uploads: UploadFolder,
    api_key: Callable[[], str],
    *,
    max_upload_bytes: int,
    hosts: HostNames | None = None,
    camera: Callable[[], tuple[bytes, str]] | None = None,
) -> WebFront:
    """The ASGI application: the routes behind the key gate (``api_key()``: the key in force,
    e.g. :meth:`cdprhost.server.apikey.KeyFile.current`; ``hosts``: the names answered to,
    by default the loopback names; ``camera``: the web page's snapshot)."""
    uploads.ensure()
    api = Api(printer, uploads)
    app = FastAPI(docs_url=None, redoc_url=None, openapi_url=None)

    @app.exception_handler(ClientDisconnect)
    async def gone(request: Request, exc: ClientDisconnect) -> Response:
        # the client left mid-body, or was cut off (too slow): nothing was stored
        log.info(
            "%s went away during %s %s", client_name(request), request.method, request.url.path
        )
        return error(400, "the client went away before its request was complete")

    @app.exception_handler(BodyTooLarge)
    async def too_large(request: Request, exc: BodyTooLarge) -> Response:
        return error(413, f"request larger than the upload cap ({max_upload_bytes} bytes)")

    def base(request: Request) -> str:
        return str(request.base_url).rstrip("/")

    @app.get("/api/version")
    async def version() -> dict[str, str]:
        return shapes.version()

    @app.get("/api/server")
    async def server() -> dict[str, Any]:
        return {"version": shapes.SERVER_VERSION, "safemode": None}

    @app.get("/api/job")
    async def get_job() -> dict[str, Any]:
        status = printer.status()
        filepos = await run_in_threadpool(api.filepos, status.file, status.job.line)
        return shapes.job(status, api.relative(status.file), filepos=filepos)

    @app.get("/api/printer")
    async def get_printer(
        exclude: str = "", history: bool = False, limit: int | None = None
    ) -> Response:
        status = printer.status()
        if not status.connected and not status.busy:
            return error(409, "Printer is not operational: no device connected")
        if limit is not None and not 0 <= limit <= 10_000:
            return error(400, f"limit: {limit} is not 0..10000")
        parts = frozenset(p.strip() for p in exclude.split(",") if p.strip())
        unknown = parts - {"temperature", "sd", "state"}
        if unknown:
            return error(400, f"exclude: {', '.join(sorted(unknown))}: not a part of the reply")
        temps = None
        if "temperature" not in parts:
            temps = await run_in_threadpool(printer.temperatures)
        count = (limit if limit is not None else 300) if history else None
        return JSONResponse(shapes.printer(status, temps, parts, count))

    @app.get("/api/settings")
    async def get_settings() -> dict[str, Any]:
        return shapes.settings()

    @app.post("/api/job")
    async def post_job(request: Request) -> Response:
        try:
            command = JobCommand.model_validate(await request.json())
        except (ValidationError, ValueError) as exc:
            text = exc.errors()[0]["msg"] if isinstance(exc, ValidationError) else "not JSON"
            return error(400, f"job command: {text}")
        try:
            if command.command == "pause":
                await run_in_threadpool(printer.pause, command.action)
            elif command.command == "cancel":
                await run_in_threadpool(printer.cancel)
            else:
                if api.selected is None or not api.selected.is_file():
                    raise Refused("no file selected: upload one with select=true first")
                selected = api.selected
                async with api.lock:
                    await run_in_threadpool(printer.check_start, selected)
                    await run_in_threadpool(printer.start, selected, client_name(request))
        except Refused as exc:
            return error(409, str(exc))
        return Response(status_code=204)

    @app.get("/api/files")
    @app.get("/api/files/local")
    async def list_files(request: Request) -> dict[str, Any]:
        entries = await run_in_threadpool(uploads.listing)
        usage = shutil.disk_usage(uploads.root)
        return {
            "files": [shapes.entry(e, base(request)) for e in entries],
            "free": usage.free,
            "total": usage.total,
        }

    @app.get("/api/files/local/{relative:path}")
    async def file_info(relative: str, request: Request) -> Response:
        try:
            path = uploads.find(relative)
        except (BadName, NotGcode) as exc:
            return error(400, str(exc))
        if path is None:
            return error(404, f"{relative}: no such file")
        st = path.stat()
        entry = Entry(path.name, uploads.relative(path), st.st_size, int(st.st_mtime))
        return JSONResponse(shapes.entry(entry, base(request)))

    @app.post("/api/files/{location}")
    async def upload(location: str, request: Request) -> Response:
        if location != "local":
            return error(404, f"{location}: only 'local' storage exists here")
        form = await request.form(max_files=1, max_fields=MAX_FIELDS)
        try:
            upload = form.get("file")
            if not isinstance(upload, UploadFile):
                return error(400, "no file: send it as the multipart field 'file'")
            try:
                start = flag(form.get("print"), "print")
                select = flag(form.get("select"), "select") or start
                path_field = form.get("path")
                if isinstance(path_field, UploadFile):
                    raise BadName("path: a form field, not a file")
                folder = check_folder(path_field)
                name = check_filename(upload.filename)
            except BadName as exc:
                return error(400, str(exc))
            except NotGcode as exc:
                return error(415, str(exc))
            who = client_name(request)
            async with api.lock:
                try:
                    final = await run_in_threadpool(api.store, upload, folder, name, start)
                except Refused as exc:
                    log.info("upload %s refused: %s", name, exc)
                    return error(409, str(exc))
                except BadName as exc:
                    return error(400, str(exc))
                await run_in_threadpool(printer.uploaded, final)
                if select:
                    api.selected = final
                if start:
                    try:
                        await run_in_threadpool(printer.start, final, who)
                    except Refused as exc:  # became busy in between: the file is kept
                        return error(409, f"{exc} (the file is stored)")
        finally:
            await form.close()
        relative = uploads.relative(final)
        reply = shapes.uploaded(name, relative, base(request), select, start)
        return JSONResponse(
            reply,
            status_code=201,
            headers={"Location": reply["files"]["local"]["refs"]["resource"]},  # percent-encoded
        )

    add_routes(app, api, camera)  # the web page's routes (behind the key) and, in front, its page
    return WebFront(KeyGuard(app, api_key, max_upload_bytes, hosts))
