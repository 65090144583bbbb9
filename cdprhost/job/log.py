"""The job log: one JSON object per line, flushed as it goes (nothing lost on a crash).

A log that cannot be written (disk full, read-only folder, ``/dev/full``) never raises
out of an event: the first failure is kept in :attr:`JobLog.failed` and the runner
stops the print safely (PrintJob checks it between steps).
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from cdprhost.jsonsafe import json_safe


class JobLog:
    """Append events to a JSON-lines file; ``None`` path = no log."""

    def __init__(self, path: str | Path | None):
        self.path = Path(path) if path else None
        self._fh: TextIO | None = None
        self.failed: OSError | None = None
        self._lock = threading.Lock()  # requests are logged from the threads that make them
        if self.path:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - held for the job, closed by close()
            except OSError as exc:
                self.failed = exc

    @property
    def problem(self) -> str | None:
        """One line naming the log and what went wrong (None while it works)."""
        if self.failed is None:
            return None
        return f"job log {self.path}: {self.failed.strerror or self.failed}"

    def write(self, kind: str, **fields: Any) -> None:
        if not self._fh or self.failed is not None:
            return
        record = {
            "t": round(time.time(), 3),
            "event": kind,
            **{k: json_safe(v) for k, v in fields.items()},
        }
        with self._lock:
            fh = self._fh
            if fh is None:
                return
            try:
                fh.write(json.dumps(record) + "\n")
                fh.flush()
            except OSError as exc:
                self.failed = exc

    def event(self, event: Any) -> None:
        self.write(type(event).__name__, **json_safe(event))

    def close(self) -> None:
        with self._lock:
            fh, self._fh = self._fh, None
        if fh is not None:
            try:
                fh.close()
            except OSError as exc:  # the last buffered bytes did not fit
                self.failed = self.failed or exc
