"""Plain, immutable data the screens display.

Backends (the real layers or test fakes) return these; the UI never reads the
lower layers' own objects directly, so a change below touches one adapter only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

Vec3 = tuple[float, float, float]


def unsigned_zero(value: float, digits: int) -> float:
    """``value`` rounded to ``digits``, a rounded -0 as 0 (so it prints "0.00", not "-0.00")."""
    rounded = round(float(value), digits)
    return 0.0 if rounded == 0 else rounded


@dataclass(frozen=True)
class PortChoice:
    """A port the user can pick: ``port`` is what ``connect`` receives; ``simulated`` marks a
    simulated device (embedded, or a ``cdprhost sim-device`` on a pseudo-terminal)."""

    port: str
    label: str
    detail: str = ""
    simulated: bool = False


@dataclass(frozen=True)
class ViolationRow:
    line: int
    rule: str
    detail: str
    point: Vec3 | None = None


@dataclass(frozen=True, eq=False)
class Toolpath:
    """The moves of a G-code file in the G-code frame (machine frame minus ``bed_origin``),
    program order, for the layer preview; ``heat_waits`` are (line, heater, target °C) of the
    program's waits for temperature, for the time estimate."""

    xy0: np.ndarray  # (n, 2) float32, move starts
    xy1: np.ndarray  # (n, 2) float32, move ends
    line: np.ndarray  # (n,) int64
    layer: np.ndarray  # (n,) int32
    extrude: np.ndarray  # (n,) bool
    layer_z: tuple[float, ...] = ()  # height of each layer (its first extrusion), mm
    heat_waits: tuple[tuple[int, str, float], ...] = ()
    bed_origin: Vec3 = (0.0, 0.0, 0.0)

    @property
    def layers(self) -> int:
        return len(self.layer_z)

    def bounds(self) -> tuple[float, float, float, float]:
        """(x min, y min, x max, y max) of the extrusions (of every move when none extrudes);
        computed once."""
        cached: tuple[float, float, float, float] | None = self.__dict__.get("_bounds")
        if cached is not None:
            return cached
        sel = self.extrude if self.extrude.any() else np.ones(len(self.line), dtype=bool)
        if not sel.any():
            box = (-1.0, -1.0, 1.0, 1.0)
        else:
            lo = np.minimum(self.xy0[sel].min(axis=0), self.xy1[sel].min(axis=0))
            hi = np.maximum(self.xy0[sel].max(axis=0), self.xy1[sel].max(axis=0))
            box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        object.__setattr__(self, "_bounds", box)
        return box


@dataclass(frozen=True)
class PreflightView:
    """Result of checking a G-code file before printing."""

    path: str
    ok: bool
    violations: tuple[ViolationRow, ...] = ()
    moves: int = 0
    layers: int = 0
    estimated_time_s: float = 0.0
    filament_mm: float = 0.0
    notes: tuple[str, ...] = ()
    toolpath: Toolpath | None = None
    placement: str = ""  # the shift applied and, for a part that does not fit, the advice


@dataclass(frozen=True)
class ResumeView:
    """A saved resume point that belongs to the open file."""

    path: str  # the resume point's file
    gcode: str
    reason: str
    layer: int  # 1-based: the layer to restart at, or (exact) the layer of ``last_line``
    last_line: int | None = None
    saved_at: float | None = None  # epoch seconds
    problem: str = ""  # why it cannot be used (file changed since, ...), "" when usable
    exact: bool = False  # names the exact move to continue at (``--resume``), not only a layer
    question: str = ""  # what the operator confirms before it starts (the CLI's words)


@dataclass(frozen=True)
class ConsoleLine:
    """One line of the console: what was sent, the reply, or something the device said."""

    kind: str  # sent | reply | error | device | notice
    text: str
    at: float = 0.0  # epoch seconds


@dataclass(frozen=True)
class JobRecord:
    """One finished print, for the job history."""

    file: str
    status: str  # done | cancelled | failed | refused
    started: float  # epoch seconds
    ended: float
    layers_done: int = 0
    layers: int = 0
    reason: str = ""
    resumed_from_layer: int | None = None  # 1-based
    resume_at: str = ""  # the resume point saved when it stopped: "line 1165 (layer 5)"

    @property
    def duration_s(self) -> float:
        return max(self.ended - self.started, 0.0)


@dataclass(frozen=True)
class DeviceStatusView:
    """What the device reports while no job runs (jog screen, idle panels)."""

    steps: tuple[int, int, int, int] | None = None
    sliders: Vec3 | None = None
    position: Vec3 | None = None
    hotend: float | None = None
    bed: float | None = None
    hotend_target: float = 0.0
    bed_target: float = 0.0
    motors_on: bool = False
    homed: bool = False
    queue_free: int | None = None
    fault: str = ""  # the device's latched fault, explained ("" when none)
    fault_clearable: bool = True  # the host may clear it (a thermal fault: no)


@dataclass(frozen=True)
class JogCheck:
    """Feasibility of a jog target, known before anything moves."""

    target: Vec3
    ok: bool
    reason: str = ""
    target_ok: bool = True  # False: the target itself is infeasible (not only the path to it)


# ----------------------------------------------------------------- calibration


@dataclass(frozen=True)
class PoseView:
    index: int  # 1-based
    point: Vec3
    role: str = "fit"  # fit | check
    status: str = "planned"  # planned | moving | settled | take ok | rejected | done
    detail: str = ""
    measured: Vec3 | None = None
    take: str = (
        ""  # a take file waiting for this pose (virtual motion capture), offered to the user
    )


@dataclass(frozen=True)
class ParameterRow:
    name: str
    before: float
    after: float
    stderr: float | None = None
    ci_low: float | None = None
    ci_high: float | None = None


@dataclass(frozen=True)
class IdentificationView:
    rows: tuple[ParameterRow, ...]
    rms_before_mm: float
    rms_after_mm: float
    iterations: int = 0
    poses_used: int = 0
    check_before_mm: float | None = None
    check_after_mm: float | None = None
    warnings: tuple[str, ...] = ()
    profile_path: str = ""
    trusted: bool | None = None  # the trust gate's verdict (None: the gate did not run)
    predicted_rms_mm: float | None = None  # the gate's predicted workspace error
    predicted_max_mm: float | None = None


@dataclass(frozen=True)
class CalibrationView:
    stage: str = "idle"  # idle | planning | planned | measuring | identifying | done | error
    poses: tuple[PoseView, ...] = ()
    current: int | None = None  # index of the pose awaiting a take
    session_dir: str = ""
    indices: tuple[tuple[str, float], ...] = ()  # observability indices of the plan
    result: IdentificationView | None = None
    message: str = ""
    camera: str = ""  # the camera taking the pictures ("": motion-capture take files)


# ------------------------------------------------------------------- diagnosis


@dataclass(frozen=True)
class CandidateRow:
    name: str
    p_value: float | None
    delta_bic: float | None
    heldout_rms_mm: float | None


@dataclass(frozen=True)
class DiagnosisView:
    verdict: str  # named | none | ambiguous | unexplained
    effect: str | None
    where: str
    candidates: tuple[CandidateRow, ...]
    heldout_rms_before_mm: float
    heldout_rms_after_mm: float
    noise_floor_mm: float
    per_pose_before_mm: tuple[float, ...] = ()
    per_pose_after_mm: tuple[float, ...] = ()
    parameters: tuple[tuple[str, str], ...] = field(default=())
