"""Resume points: where a print stopped, kept up to date while it prints.

A point is written atomically (a temporary file renamed over the old one) while the
job prints: at every layer and every few seconds, and once more when the job ends
other than by completing. It names the exact last segment the device executed (from
the device's reports, never from what was sent), as a G-code line, the point on that
move and the filament position there, plus the device segment number and boot, so a
host that was killed can ask the device how far it really got (see
:func:`refine_from_device` in the runner). Points are keyed by the file's content hash
and path: an edited file has no point, and a failed connect never touches one (the
job writes only after the device executed something).

``cdprhost print FILE --resume`` continues exactly there; ``--resume-from-layer N``
restarts at a layer (the point suggests which).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.motion.prepared import Setup

log = logging.getLogger(__name__)

VERSION = 2
#: the reason of the points a job saves while it prints (every few seconds): what a killed
#: host leaves, maybe behind the device (the host's own last point of a job is exact)
SAVED_WHILE_PRINTING = "printing"


@dataclass(frozen=True)
class ResumePoint:
    gcode: str  # absolute path of the file
    sha256: str  # of its content
    reason: str
    last_line: int | None
    last_layer: int | None  # 1-based, as shown
    position: tuple[float, float, float] | None  # machine frame
    steps: tuple[int, int, int, int] | None
    hotend_target: float
    bed_target: float
    suggested_layer: int | None
    point: tuple[float, float, float] | None = None  # G-code frame: where to continue
    e_mm: float | None = None  # the program's filament position there
    device_segment: int = 0  # device number of that segment
    boot_id: int = 0  # of the device that executed it
    first_segment: int = 0  # device number of the job's first planned segment
    plan: dict[str, Any] = field(default_factory=dict)  # how the job built its program
    setup: dict[str, Any] = field(default_factory=dict)  # placement options (`Setup.to_json`)
    placement: tuple[float, float] | None = None  # the X/Y shift they gave (mm)
    # the operator's overrides in effect (M220 / M221); a resume starts at 100 % and says so
    speed_pct: float = 100.0
    flow_pct: float = 100.0
    saved_at: str = ""
    version: int = VERSION

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        data = asdict(self)
        data["saved_at"] = time.strftime("%Y-%m-%dT%H:%M:%S")
        write_text_atomic(path, json.dumps(data, indent=1) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> ResumePoint:
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
            known = {f for f in cls.__dataclass_fields__}
            point = cls(**{k: v for k, v in data.items() if k in known})
            point.job_setup()  # validated here: a malformed setup is not a resume point
            return point
        except (OSError, ValueError, TypeError) as exc:
            raise InputError(f"not a resume point: {exc}", source=str(path)) from None

    def job_setup(self) -> Setup:
        """The placement options the job that saved this point ran with."""
        return Setup.from_json(self.setup) if self.setup else Setup()

    @property
    def exact(self) -> bool:
        """Does it name a point on a move (``--resume``), not just a layer?"""
        return self.point is not None and self.last_line is not None and self.last_line > 0


def resume_setup(point: ResumePoint, requested: Setup) -> Setup:
    """The setup a ``--resume`` of ``point`` runs with: the saved job's own, so the same
    program is rebuilt. Options given again must be the same; others are refused."""
    saved = point.job_setup()
    if requested.default or requested == saved:
        return saved
    raise InputError(
        f"the resume point was saved by a print with placement options {saved.options()!r}; "
        f"--resume continues that program, so give the same options or none "
        f"(given: {requested.options()!r})",
        source="--resume",
    )


def state_dir() -> Path:
    """Where job logs and resume points go by default (never beside the G-code)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(os.environ.get("CDPRHOST_STATE", Path(base) / "cdprhost")) / "jobs"


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def resume_path_for(
    gcode: str | Path, folder: str | Path | None = None, sha256: str | None = None
) -> Path:
    """The point of this file's content at this path."""
    g = Path(gcode)
    digest = sha256 or file_sha256(g)
    key = hashlib.sha256(f"{digest}\0{g.resolve()}".encode()).hexdigest()[:16]
    return (Path(folder) if folder else state_dir()) / f"{g.stem}-{key}.resume.json"


def find_resume_point(
    gcode: str | Path, folder: str | Path | None = None, sha256: str | None = None
) -> ResumePoint | None:
    """The saved point of this file (same content, same path), or None."""
    path = resume_path_for(gcode, folder, sha256)
    if not path.exists():
        return None
    point = ResumePoint.load(path)
    if point.sha256 != (sha256 or file_sha256(gcode)):
        return None
    return point


def resume_question(
    name: str, point: ResumePoint | None = None, layer: int | None = None, placement: str = ""
) -> str:
    """What the operator confirms before a resumed print: at the exact ``point`` (``--resume``,
    with the saved job's ``placement`` options, if any) or from ``layer`` (1-based,
    ``--resume-from-layer``)."""
    if point is not None:
        placed = f", placement {placement}" if placement else ""
        where = (
            f"at line {point.last_line} (layer {point.last_layer}{placed}, stopped: {point.reason})"
        )
    else:
        where = f"from layer {layer}"
    return (
        f"Resume {name} {where}: the machine homes, heats, and lowers onto the part. "
        "Is the part still on the bed and clear?"
    )


def remove_resume_point(gcode: str | Path, folder: str | Path | None, sha256: str) -> None:
    with contextlib.suppress(OSError):
        resume_path_for(gcode, folder, sha256).unlink()


def log_path_for(gcode: str | Path, folder: str | Path | None = None) -> Path:
    g = Path(gcode)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = Path(folder) if folder else state_dir()
    path = base / f"{g.stem}-{stamp}.jsonl"
    n = 1
    while path.exists() or path.with_suffix(".log").exists():  # two prints in one second
        n += 1
        path = base / f"{g.stem}-{stamp}-{n}.jsonl"
    return path


class ResumeWriter:
    """Saves the job's point at each new layer (at most every ``min_s``) and every
    ``every_s`` seconds while it prints (``now``: wall-clock seconds).

    A write that fails (disk full) is reported once and the previous point stays."""

    def __init__(self, path: Path, every_s: float = 3.0, min_s: float = 0.5):
        self.path = path
        self.every_s = every_s
        self.min_s = min_s
        self._last_t = -1e9
        self._last_layer: int | None = None
        self._last_segment = -1
        self.failed: OSError | None = None

    def due(self, layer: int | None, segment: int, now: float) -> bool:
        if segment == self._last_segment:
            return False
        elapsed = now - self._last_t
        return elapsed >= self.every_s or (layer != self._last_layer and elapsed >= self.min_s)

    def save(self, point: ResumePoint, now: float, layer: int | None = None) -> bool:
        try:
            point.save(self.path)
        except OSError as exc:
            if self.failed is None:
                log.warning("resume point %s not written: %s", self.path, exc.strerror or exc)
            self.failed = exc
            return False
        self.failed = None
        self._last_t = now
        self._last_layer = layer
        self._last_segment = point.device_segment
        return True
