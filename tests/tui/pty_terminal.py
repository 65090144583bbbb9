"""A program, ``cdprhost tui`` most often, on a pseudo-terminal of its own, as in a terminal
window of a given size: keys are typed into it, what it draws is read as it comes (so it never
blocks on a full terminal) and its last bytes are kept to be searched, and it is stopped at
the end. The pty is its controlling terminal: closing the window hangs it up (SIGHUP).

Used by the tests (test_service_pty.py) and by the benchmarks that drive a real terminal UI
(bench/front_end_acceptance.py, bench/tui_cpu.py, which put the repository on their path):
it lives with the tests because the package does not ship test tools, and a test never
imports a benchmark."""

from __future__ import annotations

import contextlib
import fcntl
import os
import pty
import re
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ANSI = re.compile(r"\x1b(\[[0-?]*[ -/]*[@-~]|\][^\x07\x1b]*(\x07|\x1b\\)|[PX^_][^\x1b]*\x1b\\|.)")


def screen_text(raw: bytes) -> str:
    """What a terminal shows of ``raw``, roughly: the text runs without escape sequences."""
    return ANSI.sub(" ", raw.decode("utf-8", "replace"))


def tui_argv(*args: str) -> list[str]:
    """``cdprhost tui ARGS`` with this Python."""
    return [sys.executable, "-m", "cdprhost", "tui", *args]


class PtyTerminal:
    """``argv`` on a pseudo-terminal of ``size`` (columns, rows), in ``env`` (default: this
    process's environment; the terminal's TERM and size added), from the repository's folder.
    The last ``keep`` bytes it drew are kept; ``total`` counts them all."""

    def __init__(
        self,
        argv: list[str],
        size: tuple[int, int] = (120, 40),
        env: Mapping[str, str] | None = None,
        keep: int = 400_000,
    ):
        cols, rows = size
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
        base = os.environ if env is None else env
        self.proc = subprocess.Popen(
            argv,
            stdin=slave,
            stdout=slave,
            stderr=slave,
            env={**base, "TERM": "xterm-256color", "COLUMNS": str(cols), "LINES": str(rows)},
            cwd=ROOT,
            start_new_session=True,
            preexec_fn=lambda: fcntl.ioctl(0, termios.TIOCSCTTY, 0),  # noqa: PLW1509
        )
        os.close(slave)
        self.master = master
        self.keep = keep
        self.tail = b""
        self.total = 0
        self.lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def _read(self) -> None:
        while True:
            try:
                chunk = os.read(self.master, 65536)
            except OSError:
                return
            if not chunk:
                return
            with self.lock:
                self.total += len(chunk)
                self.tail = (self.tail + chunk)[-self.keep :]

    def type(self, keys: str, pause_s: float = 0.0) -> None:
        """Type ``keys``, ``pause_s`` after each one when given (a person's pace)."""
        for key in keys if pause_s else [keys]:
            with contextlib.suppress(OSError):
                os.write(self.master, key.encode())
            if pause_s:
                time.sleep(pause_s)

    def screen(self) -> str:
        """What it drew (the kept bytes), as text."""
        with self.lock:
            return screen_text(self.tail)

    def shows(self, text: str, since: int = 0) -> bool:
        """Whether ``text`` was drawn (in the kept bytes, after byte ``since`` of its output)."""
        with self.lock:
            start = max(0, len(self.tail) - (self.total - since))
            return text in screen_text(self.tail[start:])

    def wait_for(self, text: str, timeout: float) -> str:
        """Until ``text`` is drawn: "" then; else why not (the time ran out, the program ended)."""
        deadline = time.monotonic() + timeout
        while not self.shows(text):
            if self.proc.poll() is not None:
                return f"the program ended ({self.proc.returncode}) before showing {text!r}"
            if time.monotonic() > deadline:
                return f"the screen never showed {text!r} in {timeout:g} s"
            time.sleep(0.2)
        return ""

    def stop(self, grace_s: float = 0.0) -> None:
        """End it (SIGTERM first when ``grace_s``, SIGKILL after it) and close the terminal."""
        if self.proc.poll() is None and grace_s:
            self.proc.send_signal(signal.SIGTERM)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(grace_s)
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(30)
        with contextlib.suppress(OSError):
            os.close(self.master)
