"""The job log: one JSON object per line, flushed as it goes (nothing lost on a crash)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, TextIO

from cdprhost.jsonsafe import json_safe


class JobLog:
    """Append events to a JSON-lines file; ``None`` path = no log."""

    def __init__(self, path: str | Path | None):
        self.path = Path(path) if path else None
        self._fh: TextIO | None = None
        if self.path:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - held for the job, closed by close()

    def write(self, kind: str, **fields: Any) -> None:
        if not self._fh:
            return
        record = {
            "t": round(time.time(), 3),
            "event": kind,
            **{k: json_safe(v) for k, v in fields.items()},
        }
        self._fh.write(json.dumps(record) + "\n")
        self._fh.flush()

    def event(self, event: Any) -> None:
        self.write(type(event).__name__, **json_safe(event))

    def close(self) -> None:
        if self._fh:
            self._fh.close()
            self._fh = None
