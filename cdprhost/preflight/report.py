"""The preflight report: violations (ordered by line), notes and a summary.

Pydantic models, because the report leaves the program as JSON (``check --json``).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

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


class CommandWarning(BaseModel):
    """An unknown command (skipped when printing) or parameters a printer ignores."""

    model_config = ConfigDict(frozen=True)
    word: str
    kind: str = Field(description="unknown_command or ignored_parameters")
    count: int
    lines: list[int] = Field(description=f"the first {20} lines where it appears")
    text: str = Field(description="the first occurrence as written (parameters)")


class SlicerFigures(BaseModel):
    """What the file's slicer says about it (header or footer comments)."""

    slicer: str
    filament_mm: float | None = None
    time_s: float | None = None
    exported_profile: str | None = Field(
        default=None,
        description="the cdprhost profile whose exported printer the file was sliced for",
    )


class Region(BaseModel):
    """Where the part may be at a height: the part-sized X/Y box range that fits (G-code frame)."""

    z: float = Field(description="G-code height (mm) where the allowed region is smallest")
    x: tuple[float, float]
    y: tuple[float, float]
    area_mm2: float


class PlacementReport(BaseModel):
    """Where the part is, where it may go, and how far to move it (G-code frame, mm)."""

    offset: tuple[float, float] = Field(description="X/Y shift applied to the file")
    part_min: tuple[float, float, float] | None
    part_max: tuple[float, float, float] | None
    allowed: Region | None = Field(default=None, description="allowed region at the worst height")
    fit_offset: tuple[float, float] | None = Field(
        default=None, description="an --offset X,Y that fits the part, if one exists"
    )


class RetargetReport(BaseModel):
    """What ``--retarget`` replaced."""

    start_lines: tuple[int, int] | None = Field(description="replaced start block (first, last)")
    end_lines: tuple[int, int] | None = Field(description="replaced end block (first, last)")
    found_by: str = Field(description="slicer markers or first/last extruding move")
    replaced: list[str] = Field(description="commands of the replaced blocks, counted")
    purge_lines: list[str] = Field(
        default_factory=list,
        description="purge moves of a start G-code found inside the first layer (replaced)",
    )
    hotend_c: float = Field(description="{hotend_c} of the profile's start G-code")
    bed_c: float = Field(description="{bed_c} of the profile's start G-code")


class Box(BaseModel):
    min: tuple[float, float, float]
    max: tuple[float, float, float]


class BoardReport(BaseModel):
    """The board the estimate is for: its step rate, and what it costs against the
    profile's own limits."""

    max_step_rate: int
    min_segment_s: float | None = None
    source: str = Field(
        description="'profile': the profile's [device] record; 'device': as connected"
    )
    time_at_profile_limits_s: float = Field(description="the estimate without the board's limit")
    slowed_axes: dict[str, float] = Field(
        default_factory=dict, description="axis -> its share of the time the board costs"
    )
    message: str = Field(
        default="", description="how much the board slows the print and why; empty: not at all"
    )


class PreflightReport(BaseModel):
    source: str
    profile: str
    ok: bool
    violations: list[Violation]
    violations_total: int
    violations_by_rule: dict[str, int]
    notes: list[Note]
    warnings: list[CommandWarning] = Field(default_factory=list)
    warnings_total: int = 0
    strict: bool = False
    objects: list[str] = Field(default_factory=list)
    object_labels: dict[str, str] = Field(default_factory=dict)  # name -> the file's label
    cancelled_objects: list[str] = Field(default_factory=list)
    moves: int
    layers: int
    filament_mm: float = Field(
        description="net extrusion as the file programs it (the slicer's figure)"
    )
    filament_fed_mm: float = Field(
        default=0.0, description="what the extruder feeds, after the flow factor (M221)"
    )
    estimated_time_s: float = Field(description="on the board's limits when it is known")
    board: BoardReport | None = None
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
    slicer: SlicerFigures | None = None
    placement: PlacementReport | None = None
    retarget: RetargetReport | None = None


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

    def count(self, rule: str, n: int) -> None:
        """``n`` more violations of ``rule`` beyond the stored ones (counted only)."""
        self.counts[rule] += n

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def ordered(self) -> list[Violation]:
        """Kept violations by line (stable: rules found earlier on a line first)."""
        return sorted(self._kept, key=lambda v: v.line)


@dataclass
class _NoteEntry:
    line: int
    count: int
    text: str


class NoteLog:
    """Harmless unknown commands, one entry per command word."""

    def __init__(self) -> None:
        self._notes: dict[str, _NoteEntry] = {}

    def add(self, line: int, word: str, text: str) -> None:
        entry = self._notes.get(word)
        if entry is None:
            self._notes[word] = _NoteEntry(line, 1, text)
        else:
            entry.count += 1

    def ordered(self) -> list[Note]:
        notes = [
            Note(line=e.line, word=w, count=e.count, text=e.text) for w, e in self._notes.items()
        ]
        return sorted(notes, key=lambda n: n.line)


class WarningLog:
    """Unknown commands and ignored parameters, one entry per word (first lines kept)."""

    def __init__(self, keep_lines: int = 20) -> None:
        self.keep_lines = keep_lines
        self._entries: dict[tuple[str, str], tuple[list[int], list[int], str]] = {}
        self.total = 0

    def add(self, line: int, word: str, kind: str, text: str) -> None:
        self.total += 1
        entry = self._entries.get((kind, word))
        if entry is None:
            self._entries[(kind, word)] = ([1], [line], text)
            return
        entry[0][0] += 1
        if len(entry[1]) < self.keep_lines:
            entry[1].append(line)

    def ordered(self) -> list[CommandWarning]:
        out = [
            CommandWarning(word=word, kind=kind, count=count[0], lines=lines, text=text)
            for (kind, word), (count, lines, text) in self._entries.items()
        ]
        return sorted(out, key=lambda w: w.lines[0])


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
