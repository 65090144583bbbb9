"""Logging while the terminal UI owns the terminal: never on stderr (it would be drawn over
the screen), but in a log file and, warnings and errors, in the console.

:func:`route_logging` takes the stderr handlers off the root and ``cdprhost`` loggers, adds a
file handler and a handler that queues records for the console, and returns the function
that puts everything back. The queue is drained in the UI thread (``post`` wakes it).
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections import deque
from collections.abc import Callable
from pathlib import Path

from cdprhost.logs import FORMAT
from cdprhost.tui.control.views import ConsoleLine

QUEUED = 200


class ConsoleHandler(logging.Handler):
    """Records as console lines in a bounded queue; ``wake`` is called after each put (from
    any thread)."""

    def __init__(self, wake: Callable[[], object], level: int = logging.WARNING):
        super().__init__(level)
        self.lines: deque[ConsoleLine] = deque(maxlen=QUEUED)
        self._wake = wake

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = f"{record.name}: {record.getMessage()}"
        except Exception:  # noqa: BLE001 - a bad format string must not break the UI
            text = f"{record.name}: {record.msg!r}"
        kind = "error" if record.levelno >= logging.ERROR else "device"
        self.lines.append(ConsoleLine(kind, text, record.created))
        with contextlib.suppress(Exception):
            self._wake()

    def drain(self) -> list[ConsoleLine]:
        out = []
        while self.lines:
            out.append(self.lines.popleft())
        return out


def _to_terminal(handler: logging.Handler) -> bool:
    stream = getattr(handler, "stream", None)
    return isinstance(handler, logging.StreamHandler) and stream in (
        sys.stderr,
        sys.stdout,
        sys.__stderr__,
        sys.__stdout__,
    )


def route_logging(console: ConsoleHandler, log_file: Path | None) -> Callable[[], None]:
    """Route logging away from the terminal (see the module); returns the undo."""
    root = logging.getLogger()
    taken: list[tuple[logging.Logger, logging.Handler]] = []
    for logger in (root, logging.getLogger("cdprhost")):
        for h in list(logger.handlers):
            if _to_terminal(h):
                logger.removeHandler(h)
                taken.append((logger, h))
    added: list[logging.Handler] = [console]
    if log_file is not None:
        with contextlib.suppress(OSError):
            log_file.parent.mkdir(parents=True, exist_ok=True)
            file_handler = logging.FileHandler(log_file, encoding="utf-8")
            file_handler.setLevel(logging.INFO)
            file_handler.setFormatter(logging.Formatter(FORMAT))
            added.append(file_handler)
    for h in added:
        root.addHandler(h)
    last_resort, logging.lastResort = logging.lastResort, None

    def undo() -> None:
        logging.lastResort = last_resort
        for h in added:
            root.removeHandler(h)
            with contextlib.suppress(OSError):
                h.close()
        for logger, h in taken:
            logger.addHandler(h)

    return undo
