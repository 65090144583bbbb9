"""The job log: one JSON object per line, flushed as it goes (nothing lost on a crash)."""

from __future__ import annotations

import dataclasses
import json
import time
from enum import Enum
from pathlib import Path
from typing import Any, TextIO


def _plain(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {k: _plain(v) for k, v in dataclasses.asdict(obj).items()}
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


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
            **{k: _plain(v) for k, v in fields.items()},
        }
        self._fh.write(json.dumps(record) + "\n")
        self._fh.flush()

    def event(self, event: Any) -> None:
        self.write(type(event).__name__, **_plain(event))

    def close(self) -> None:
        if self._fh:
            self._fh.close()
            self._fh = None
