"""What a print job is given (:class:`PrintOptions`) and what it returns (:class:`PrintResult`:
the contract's ``print --json`` fields)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdprhost.gcode.errors import GcodeError
from cdprhost.job.resume import ResumePoint
from cdprhost.motion.prepared import Setup
from cdprhost.profile.device_record import DeviceRecord


@dataclass
class PrintOptions:
    setup: Setup = field(default_factory=Setup)  # placement, --retarget, cancelled objects
    resume_from_layer: int | None = None  # 0-based
    resume: ResumePoint | None = None  # continue exactly at this point (``--resume``)
    log_path: str | Path | None = None
    resume_dir: str | Path | None = None
    idle_timeout_s: float = 30.0  # longest the device may show no progress while it should move
    resume_every_s: float = 3.0  # the resume point is saved this often (wall clock) ...
    resume_layer_s: float = 0.5  # ... and at each new layer, at most this often
    batch_moves: int = 1024  # planner chunk: small enough to keep the device queue fed
    clear_fault: bool = True  # a device fault is cleared at start (False: refused; ask first)
    # what the board announced, when it differs from the profile's record: kept by this
    # (the front end writes it beside the profile; None: not kept)
    record_device: Callable[[DeviceRecord], object] | None = None


@dataclass
class PrintResult:
    status: str
    segments: int = 0
    retransmits: int = 0
    final_steps: list[int] | None = None
    last_line: int | None = None
    last_layer: int | None = None
    print_time_s: float = 0.0
    estimated_time_s: float = 0.0
    violations: list[dict[str, Any]] = field(default_factory=list)
    reason: str = ""
    resume_file: str | None = None
    notices: list[str] = field(default_factory=list)
    board: str = ""  # how much the board slows the print against the profile, and why
    # the host's own timeliness: the latest it came to refill the device (s), and the most
    # motion it then kept ahead (the low watermark raised for it, s; link/flow.py)
    host_late_s: float = 0.0
    lead_s: float = 0.0
    bad_input: bool = False  # failed on bad input (a port that does not exist): exit 2

    @property
    def exit_code(self) -> int:
        if self.status == "completed":
            return 0
        return 2 if self.bad_input else 1

    @classmethod
    def syntax_refusal(cls, exc: GcodeError) -> PrintResult:
        """Refused: a line that does not parse (exit status 2)."""
        return cls(
            "refused",
            reason=str(exc),
            last_line=exc.line,
            violations=[{"line": exc.line, "rule": "syntax", "point": None, "detail": exc.reason}],
        )

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "bad_input"}


def violations_reason(report: Any) -> str:
    """A refused job's reason: the first violation and the advice."""
    from cdprhost.preflight.render import advice

    v = report.violations[0]
    lines = [
        f"{report.violations_total} violation(s); first at line {v.line}: {v.rule}: {v.detail}",
        *(line.strip() for line in advice(report)),
    ]
    return "\n".join(lines)
