"""`cdprhost sim-device` and `cdprhost print` as separate processes on a real pty.

Timing-robust on a loaded machine: every wait polls a condition with a generous
deadline; nothing asserts how long anything took.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

PYTHON = [sys.executable, "-m", "cdprhost"]


def wait_until(
    cond: Callable[[], object], timeout: float = 60.0, what: str = "condition"
) -> object:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = cond()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"{what} did not happen within {timeout:g} s")


class SimDeviceProcess:
    """``cdprhost sim-device`` on a pty; its stderr lines are collected as they come."""

    def __init__(self, tmp: Path, *args: str, env: dict[str, str] | None = None):
        self.record = tmp / "record.jsonl"
        self.proc = subprocess.Popen(
            [*PYTHON, "sim-device", "--record", str(self.record), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        assert self.proc.stdout is not None and self.proc.stderr is not None
        self.path = self.proc.stdout.readline().strip()
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()
        assert self.path.startswith("/dev/"), f"sim-device printed {self.path!r}"

    def _pump(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.put(line.rstrip("\n"))

    def stderr_has(self, text: str) -> bool:
        while not self.lines.empty():
            self.seen.append(self.lines.get())
        return any(text in line for line in self.seen)

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(20)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()

    def records(self) -> list[dict]:
        return [json.loads(line) for line in self.record.read_text().splitlines() if line.strip()]

    def __enter__(self) -> SimDeviceProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc.poll() is None:
            self.stop()


def printing_point(gcode: Path, state: Path, segments: int = 20) -> object:
    """Wait until the job's resume point (written while printing) names more than
    ``segments`` executed segments; the point."""
    from cdprhost.job.resume import ResumePoint, resume_path_for

    path = resume_path_for(gcode, state / "jobs")

    def ready() -> object:
        if not path.exists():
            return None
        point = ResumePoint.load(path)
        return point if point.device_segment > segments else None

    return wait_until(ready, 120, "a resume point written while printing")


def service_pid(port: str | None, state: Path) -> int:
    """The pid of the printer service that drives ``port`` for ``cdprhost print`` processes
    started with this ``state`` folder (they name their service by it)."""
    from cdprhost.service.paths import files_for_port

    saved = os.environ.get("CDPRHOST_STATE")
    os.environ["CDPRHOST_STATE"] = str(state)
    try:
        files = files_for_port(port)
    finally:
        if saved is None:
            del os.environ["CDPRHOST_STATE"]
        else:
            os.environ["CDPRHOST_STATE"] = saved
    return wait_until(files.read_pid, 30, "the printer service's pid file")  # type: ignore[return-value]


def signal_service(port: str, state: Path, sig: int) -> int:
    """Send ``sig`` to the printer service of ``port``; its pid."""
    pid = service_pid(port, state)
    os.kill(pid, sig)
    return pid


def kill_and_wait(pid: int, timeout_s: float = 30.0) -> None:
    """SIGKILL ``pid`` (not our child: a detached service) and wait until it has exited, so
    that its ports and locks are closed (the signal only asks; the exit comes later)."""

    def gone() -> bool:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                return fh.read().rsplit(")", 1)[1].split()[0] == "Z"  # a zombie holds no file
        except (FileNotFoundError, ProcessLookupError):
            return True

    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    wait_until(gone, timeout_s, f"process {pid} to exit after SIGKILL")


def start_print(gcode: Path, port: str, state: Path, *extra: str) -> subprocess.Popen[str]:
    """``cdprhost print`` in its own process (so the test can kill or stop it)."""
    env = {**os.environ, "CDPRHOST_STATE": str(state)}
    return subprocess.Popen(
        [*PYTHON, "print", str(gcode), "--profile", "paper-prototype", "--port", port, *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def square_part(path: Path, layers: int = 12, *, hotend_c: int = 200) -> Path:
    """A small part: heaters on (no wait), ``layers`` layers of square perimeters."""
    lines = ["G28", f"M104 S{hotend_c}", "M140 S60", "G92 E0", "M106 S128"]
    e = 0.0
    for n in range(layers):
        lines += [";LAYER_CHANGE", f"G1 Z{0.3 * (n + 1):.2f} F3000"]
        for x, y in [(20, 0), (20, 20), (0, 20), (0, 0)] * 4:
            e += 1.0
            lines.append(f"G1 X{x} Y{y} E{e:.3f} F1800")
        lines += [f"G1 E{e - 1:.3f} F2400", f"G1 E{e:.3f}"]
    path.write_text("\n".join([*lines, "M104 S0", "M140 S0", "M107"]) + "\n")
    return path
