"""The preflight report: violations (ordered by line), notes and a summary.

Pydantic models, because the report leaves the program as JSON (``check --json``).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

#: stored violations per rule; the rest are only counted
MAX_PER_RULE = 200


class Violation(BaseModel):
    model_config = ConfigDict(frozen=True)
    line: int = Field(description="1-based G-code line")
    rule: str = Field(
        description="tension, slider_travel, build_volume, cold_extrusion, volumetric_flow, "
        "temperature, unknown_command"
    )
    point: tuple[float, float, float] = Field(description="machine-frame point (mm) where it fails")
    detail: str


class Note(BaseModel):
    model_config = ConfigDict(frozen=True)
    line: int = Field(description="first line where it appears")
    word: str
    count: int
    text: str


class Box(BaseModel):
    min: tuple[float, float, float]
    max: tuple[float, float, float]


class PreflightReport(BaseModel):
    source: str
    profile: str
    ok: bool
    violations: list[Violation]
    violations_total: int
    violations_by_rule: dict[str, int]
    notes: list[Note]
    moves: int
    layers: int
    filament_mm: float
    estimated_time_s: float
    moves_slowed_by_modules: int
    moves_sampled_densely: int
    motion_box_machine: Box | None = Field(
        description="all effector positions, home included (machine frame)"
    )
    print_box_gcode: Box | None = Field(
        description="extruding moves (G-code frame): the printed part"
    )
    min_extrude_temp_c: float
    max_volumetric_flow_mm3_s: float
    max_volumetric_flow_seen_mm3_s: float


def point3(p: np.ndarray) -> tuple[float, float, float]:
    return (round(float(p[0]), 4), round(float(p[1]), 4), round(float(p[2]), 4))


class ViolationLog:
    """Collects violations; keeps the first ``MAX_PER_RULE`` of each rule, counts all."""

    def __init__(self, per_rule: int = MAX_PER_RULE):
        self.per_rule = per_rule
        self.counts: Counter[str] = Counter()
        self._kept: list[Violation] = []

    def add(self, line: int, rule: str, point: np.ndarray, detail: str) -> None:
        self.counts[rule] += 1
        if self.counts[rule] <= self.per_rule:
            self._kept.append(
                Violation(line=int(line), rule=rule, point=point3(point), detail=detail)
            )

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def ordered(self) -> list[Violation]:
        """Kept violations by line (stable: rules found earlier on a line first)."""
        return sorted(self._kept, key=lambda v: v.line)


class NoteLog:
    """Harmless unknown commands, one entry per command word."""

    def __init__(self) -> None:
        self._notes: dict[str, list] = {}  # word -> [first line, count, text]

    def add(self, line: int, word: str, text: str) -> None:
        entry = self._notes.get(word)
        if entry is None:
            self._notes[word] = [line, 1, text]
        else:
            entry[1] += 1

    def ordered(self) -> list[Note]:
        notes = [Note(line=v[0], word=w, count=v[1], text=v[2]) for w, v in self._notes.items()]
        return sorted(notes, key=lambda n: n.line)


class BoxAccumulator:
    def __init__(self) -> None:
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)

    def add(self, points: np.ndarray) -> None:
        if points.size:  # column by column: much faster than reducing along axis 0
            lo = np.array([points[:, k].min() for k in range(3)])
            hi = np.array([points[:, k].max() for k in range(3)])
            self.lo = np.minimum(self.lo, lo)
            self.hi = np.maximum(self.hi, hi)

    def box(self, shift: np.ndarray | None = None) -> Box | None:
        if not np.isfinite(self.lo).all():
            return None
        s = np.zeros(3) if shift is None else shift
        return Box(min=point3(self.lo - s), max=point3(self.hi - s))
