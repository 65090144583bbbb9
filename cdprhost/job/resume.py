"""Resume points: where a failed print stopped, saved atomically beside the job log.

``cdprhost print FILE --resume-from-layer N`` restarts from layer N after the user
confirms; the saved point tells the user which layer to give (the layer that was
being printed when the job stopped) and records the device state for the log.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic


@dataclass(frozen=True)
class ResumePoint:
    gcode: str
    reason: str
    last_line: int | None
    last_layer: int | None
    position: tuple[float, float, float] | None
    steps: tuple[int, int, int, int] | None
    hotend_target: float
    bed_target: float
    suggested_layer: int | None

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        write_text_atomic(path, json.dumps(asdict(self), indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> ResumePoint:
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
            return cls(**data)
        except (OSError, ValueError, TypeError) as exc:
            raise InputError(f"not a resume point: {exc}", source=str(path)) from None


def state_dir() -> Path:
    """Where job logs and resume points go by default (never beside the G-code)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(os.environ.get("CDPRHOST_STATE", Path(base) / "cdprhost")) / "jobs"


def resume_path_for(gcode: str | Path, folder: str | Path | None = None) -> Path:
    g = Path(gcode)
    return (Path(folder) if folder else state_dir()) / f"{g.stem}.resume.json"


def log_path_for(gcode: str | Path, folder: str | Path | None = None) -> Path:
    g = Path(gcode)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return (Path(folder) if folder else state_dir()) / f"{g.stem}-{stamp}.jsonl"
