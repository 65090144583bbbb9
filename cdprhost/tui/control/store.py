"""What the terminal UI keeps between runs: recent files, the job history, screenshots.

Everything lives in one folder beside the job logs (``<state>/tui``, where ``<state>`` is
``$CDPRHOST_STATE`` or ``~/.local/state/cdprhost``). Files are small, written atomically or
appended one line at a time; a damaged line or file is skipped, never fatal.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import asdict
from pathlib import Path

from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.job.resume import state_dir
from cdprhost.tui.control.views import JobRecord

RECENT_MAX = 15
HISTORY_MAX = 500
"""The newest finished prints the UI holds and shows (the history file keeps every one)."""


def tui_dir() -> Path:
    return state_dir().parent / "tui"


def screenshot_dir() -> Path:
    """Where screenshots go (created on demand)."""
    folder = tui_dir() / "screenshots"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


class RecentFiles:
    """Recently opened G-code files, newest first; files that have gone are dropped."""

    def __init__(self, path: Path | None = None):
        self.path = path or tui_dir() / "recent.json"

    def load(self) -> tuple[str, ...]:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return ()
        if not isinstance(data, list):
            return ()
        return tuple(p for p in data if isinstance(p, str) and os.path.isfile(p))[:RECENT_MAX]

    def add(self, file: str) -> tuple[str, ...]:
        file = os.path.abspath(file)
        recent = (file, *(p for p in self.load() if p != file))[:RECENT_MAX]
        with contextlib.suppress(OSError):  # a read-only state folder must not stop a print
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_text_atomic(self.path, json.dumps(list(recent), indent=1) + "\n")
        return recent


class JobHistory:
    """Finished prints, one JSON line each, oldest first in the file."""

    def __init__(self, path: Path | None = None):
        self.path = path or tui_dir() / "history.jsonl"

    def load(self, limit: int = HISTORY_MAX) -> tuple[JobRecord, ...]:
        """The newest ``limit`` records, newest first."""
        try:
            lines = self.path.read_text(encoding="utf-8").splitlines()
        except OSError:
            return ()
        out: list[JobRecord] = []
        for text in reversed(lines):
            try:
                out.append(JobRecord(**json.loads(text)))
            except (ValueError, TypeError):
                continue
            if len(out) >= limit:
                break
        return tuple(out)

    def append(self, record: JobRecord) -> None:
        with contextlib.suppress(OSError):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("a", encoding="utf-8") as f:
                f.write(json.dumps(asdict(record)) + "\n")
