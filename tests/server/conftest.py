"""A print server on 127.0.0.1 (ephemeral port) with the embedded simulated device, and a
small HTTP client over loopback. Every wait is a bounded poll; nothing asserts a duration."""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from cdprhost.profile import load_profile
from cdprhost.server.apikey import KeyFile, read_key
from cdprhost.server.app import create_app
from cdprhost.server.connections import ConnectionLimits
from cdprhost.server.headless import HeadlessPrinter
from cdprhost.server.listen import ServerThread
from cdprhost.server.uploads import UploadFolder
from cdprhost.sim.embedded import open_embedded

PROFILE = "paper-prototype"


def small_part(layers: int = 3, side: float = 20.0, *, heat_wait: bool = True) -> str:
    """A tiny printable part (heats, squares on a few layers). ``heat_wait`` False: the
    hotend's target is set but not waited for (M109: 75 s of device time from cold)."""
    lines = ["G28", "M140 S40", "M104 S200", *(["M109 S200"] if heat_wait else []), "G92 E0"]
    e = 0.0
    for n in range(layers):
        lines += [";LAYER_CHANGE", f"G1 Z{0.3 * (n + 1):.2f} F3000"]
        for x, y in [(side, 0), (side, side), (0, side), (0, 0)]:
            e += 1.0
            lines.append(f"G1 X{x:g} Y{y:g} E{e:.3f} F1800")
    return "\n".join([*lines, "M104 S0", "M140 S0", ""])


OUTSIDE = "G28\nG1 Z1 F1200\nG1 X5000 Y0 F1200\n"  # far outside every workspace


def wait_job(
    get: Callable[[], dict[str, Any]], cond: Callable[[dict[str, Any]], bool], timeout: float
) -> dict[str, Any]:
    """Poll ``GET /api/job`` until ``cond`` holds (bounded)."""
    end = time.monotonic() + timeout
    last: dict[str, Any] = {}
    while time.monotonic() < end:
        last = get()
        if cond(last):
            return last
        time.sleep(0.05)
    raise AssertionError(f"job did not reach the condition within {timeout:g} s: {last}")


@dataclass
class Reply:
    status: int
    headers: dict[str, str]
    body: bytes

    def json(self) -> Any:
        return json.loads(self.body)


@dataclass
class Server:
    url: str
    port: int
    key: str
    uploads: Path
    printer: HeadlessPrinter
    thread: ServerThread
    links: list[Any] = field(default_factory=list)

    def request(
        self,
        method: str,
        path: str,
        body: bytes | None = None,
        headers: dict[str, str] | None = None,
        key: str | bool | None = True,
    ) -> Reply:
        hdrs = dict(headers or {})
        if key is True:
            hdrs["X-Api-Key"] = self.key
        elif isinstance(key, str):
            hdrs["X-Api-Key"] = key
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
        try:
            conn.request(method, path, body=body, headers=hdrs)
            resp = conn.getresponse()
            return Reply(resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read())
        finally:
            conn.close()

    def job(self) -> dict[str, Any]:
        reply = self.request("GET", "/api/job")
        assert reply.status == 200, reply
        return reply.json()

    def wait_job(self, cond: Callable[[dict[str, Any]], bool], timeout: float = 120.0) -> dict:
        return wait_job(self.job, cond, timeout)

    def stored(self) -> list[str]:
        """Every file under the upload folder (staging included)."""
        return sorted(
            p.relative_to(self.uploads).as_posix() for p in self.uploads.rglob("*") if p.is_file()
        )


def multipart(
    fields: list[tuple[str, str]],
    file: tuple[str, bytes] | None,
    boundary: str = "cdprhost-test-boundary",
    file_field: str = "file",
) -> tuple[bytes, str]:
    out = b""
    for name, value in fields:
        out += (
            f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'
        ).encode()
    if file is not None:
        fname, data = file
        out += (
            (
                f'--{boundary}\r\nContent-Disposition: form-data; name="{file_field}"; '
                f'filename="{fname}"\r\nContent-Type: application/octet-stream\r\n\r\n'
            ).encode()
            + data
            + b"\r\n"
        )
    out += f"--{boundary}--\r\n".encode()
    return out, f"multipart/form-data; boundary={boundary}"


NOFILE_EXEC = (
    "import os, resource, sys; "
    "hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]; "
    "resource.setrlimit(resource.RLIMIT_NOFILE, (int(sys.argv[1]), hard)); "
    "os.execv(sys.executable, [sys.executable, *sys.argv[2:]])"
)


class ServeProcess:
    """``cdprhost serve`` in its own process on 127.0.0.1 (ephemeral port): url, key, and a
    bounded wait for its job state."""

    def __init__(self, tmp: Path, *args: str, nofile: int | None = None):
        """``nofile``: the server's soft limit of open descriptors."""
        self.env = {
            **os.environ,
            "XDG_CONFIG_HOME": str(tmp / "cfg"),
            "CDPRHOST_STATE": str(tmp / "state"),
        }
        cmd = [sys.executable, "-m", "cdprhost", "serve", "-p", PROFILE, "--listen", "127.0.0.1:0"]
        if nofile is not None:  # set in the child, then the server exec'd in its place
            cmd = [sys.executable, "-c", NOFILE_EXEC, str(nofile), *cmd[1:]]
        self.proc = subprocess.Popen([*cmd, *args], env=self.env, stderr=subprocess.PIPE, text=True)
        assert self.proc.stderr is not None
        lines = []
        for _ in range(50):  # bounded: the banner comes within a few lines
            line = self.proc.stderr.readline()
            lines.append(line)
            if "upload API on" in line or not line:
                break
        self.banner = "".join(lines)
        found = re.search(r"http://127\.0\.0\.1:(\d+)", self.banner)
        assert found, self.banner
        self.url, self.port = found.group(0), int(found.group(1))
        self.key = read_key(tmp / "cfg" / "cdprhost" / "api-key") or ""
        self.uploads = tmp / "state" / "uploads"

    def job(self) -> dict[str, Any]:
        req = urllib.request.Request(self.url + "/api/job", headers={"X-Api-Key": self.key})
        with urllib.request.urlopen(req, timeout=60) as resp:
            return dict(json.loads(resp.read()))

    def wait_job(self, cond: Callable[[dict[str, Any]], bool], timeout: float = 120.0) -> dict:
        return wait_job(self.job, cond, timeout)

    def stop(self, sig: int = signal.SIGTERM) -> tuple[int, str]:
        """Signal it; (exit status, the rest of its stderr)."""
        try:
            self.proc.send_signal(sig)
            rest = self.proc.communicate(timeout=120)[1]
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait(timeout=30)
        return self.proc.returncode, rest


def printed_to_the_end(job: dict[str, Any]) -> bool:
    return job["state"] == "Operational" and job["progress"]["completion"] == 100.0


@pytest.fixture
def serve(tmp_path) -> Iterator[Callable[..., ServeProcess]]:
    made: list[ServeProcess] = []

    def start(*args: str, nofile: int | None = None) -> ServeProcess:
        made.append(ServeProcess(tmp_path / f"serve{len(made)}", *args, nofile=nofile))
        return made[-1]

    yield start
    for p in made:
        if p.proc.poll() is None:
            p.stop()


@pytest.fixture
def config_home(tmp_path, monkeypatch) -> Path:
    home = tmp_path / "config"
    monkeypatch.setenv("XDG_CONFIG_HOME", str(home))
    return home


@pytest.fixture
def make_server(tmp_path, config_home) -> Iterator[Callable[..., Server]]:
    made: list[Server] = []

    def make(
        speedup: float | None = None,
        max_upload_bytes: int = 2_000_000,
        limits: ConnectionLimits | None = None,
        printer: Any = None,
    ) -> Server:
        """``printer``: a stand-in for the headless printer (None: the real one)."""
        profile = load_profile(PROFILE)
        links: list[Any] = []

        def open_device() -> Any:
            link = open_embedded(speedup=speedup)
            links.append(link)
            return link

        printer = printer or HeadlessPrinter(profile, open_device)
        keys = KeyFile()
        uploads = UploadFolder(tmp_path / f"uploads{len(made)}")
        app = create_app(printer, uploads, keys.current, max_upload_bytes=max_upload_bytes)
        thread = ServerThread(app, "127.0.0.1", 0, limits)
        thread.start()
        server = Server(thread.url, thread.port, keys.key, uploads.root, printer, thread, links)
        made.append(server)
        return server

    yield make
    for server in made:
        server.printer.shutdown("test over", timeout_s=30)
        server.thread.stop()
