"""Preflight of a whole G-code program, streamed: nothing moves until this passes.

One pass over the reader's items: every move's whole path against the workspace
(from the home point to the first move as well), extrusion sanity, heater
targets, unknown commands; the planner runs alongside for the time estimate and
the moves the module limits slow down. The estimate is for the board: its announced
step rate (the profile's ``[device]`` record, or what a connected device announced)
caps the speeds as the print job will; when it does, a second planner at the
profile's own limits runs too, and the report says by how much the board slows the
print and which axes it holds back. Parse errors (`GcodeError`, exit 2)
propagate unchanged.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import replace
from typing import Any

import numpy as np

from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.items import (
    ColdExtrusion,
    IgnoredParameters,
    LayerChange,
    MoveChunk,
    ObjectDefine,
    ObjectStart,
    ProgramItem,
    SetTemperature,
    UnknownCommand,
)
from cdprhost.gcode.placement import PartExtent
from cdprhost.gcode.slicer_header import read_slicer_figures
from cdprhost.gcode.summary import ProgramSummary
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.device_limits import (
    busiest_axis,
    caps_for_device,
    slowdown_message,
    slowed_axes,
)
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.prepared import Prepared, Setup, prepare
from cdprhost.motion.program import MarkedMoves, ProgramPlanner
from cdprhost.preflight.extrusion import (
    ExtrusionLimits,
    cold_detail,
    cold_extrusion,
    temperature_problem,
    volumetric_flow,
)
from cdprhost.preflight.placement import placement_report
from cdprhost.preflight.report import (
    BoardReport,
    BoxAccumulator,
    NoteLog,
    PreflightReport,
    RetargetReport,
    SlicerFigures,
    ViolationLog,
    WarningLog,
)
from cdprhost.preflight.workspace import PathChecker
from cdprhost.profile.device_record import DeviceRecord
from cdprhost.profile.models import MachineProfile


class Preflight:
    """Incremental preflight: feed items with :meth:`add`, then :meth:`report`."""

    def __init__(
        self,
        profile: MachineProfile,
        model: MachineModel | None = None,
        *,
        source: str = "<program>",
        limits: ExtrusionLimits | None = None,
        strict: bool = False,
        device: DeviceRecord | None = None,
        **planner_options: Any,
    ):
        """``device``: the limits a connected board announced (default: the profile's
        ``[device]`` record; neither: the profile's own limits)."""
        self.profile = profile
        self.strict = strict
        self.model = model or MachineModel.from_profile(profile)
        self.source = source
        self.limits = limits or ExtrusionLimits.from_profile(profile)
        self.device = device or profile.device
        self.device_source = "device" if device is not None else "profile"
        plan_profile = profile
        self.free: ProgramPlanner | None = None  # at the profile's limits, when the board slows it
        if self.device is not None:
            caps = caps_for_device(
                profile,
                self.device.max_step_rate,
                self.device.min_segment_s,
                total_step_rate=self.device.total_step_rate,
            )
            if caps.profile is not profile:  # the board slows it (its rates, its budget)
                plan_profile = caps.profile
                self.free = ProgramPlanner(
                    profile, self.model, chord=False, marked=True, **planner_options
                )
        self.planner = ProgramPlanner(
            plan_profile, self.model, chord=False, marked=True, **planner_options
        )
        self.axis_time = np.zeros(4)  # s of planned moves per busiest axis (the board's plan)
        self.free_axis_time = np.zeros(4)  # the same at the profile's own limits
        self.checker = PathChecker(self.model)
        self.violations = ViolationLog()
        self.notes = NoteLog()
        self.warnings = WarningLog()
        self.summary = ProgramSummary()
        self.objects: dict[str, str] = {}  # name -> label (M486 A, Klipper NAME)
        self.extent = PartExtent()
        self.cold_allowed = False
        self.motion_box = BoxAccumulator()
        self.print_box = BoxAccumulator()
        self.motion_box.add(self.planner.home[None, :])
        self.hotend_c: float | None = None
        self.layers = 0
        self.slowed = 0
        self.max_flow = 0.0

    def add(self, item: ProgramItem) -> None:
        self.summary.add(item)
        match item:
            case MoveChunk():
                self._chunk(item)
                return
            case SetTemperature():
                problem = temperature_problem(item, self.limits)
                if problem:
                    self.violations.add(item.line, "temperature", self.planner.position, problem)
                if item.heater == "hotend":
                    self.hotend_c = item.target_c
            case UnknownCommand(harmless=True):
                self.notes.add(item.line, item.word, item.text)
            case UnknownCommand():
                self._unexpected(
                    item.line,
                    item.word,
                    "unknown_command",
                    item.text,
                    f"{item.word} is not a command this machine knows; "
                    + ("refused (--strict)" if self.strict else "skipped when printing"),
                )
            case IgnoredParameters():
                self._unexpected(
                    item.line,
                    item.word,
                    "ignored_parameters",
                    item.letters,
                    f"{item.letters} on {item.word} means nothing to this machine: ignored",
                )
            case ColdExtrusion(allow=allow, min_temp_c=min_temp):
                if allow is not None:
                    self.cold_allowed = allow
                if min_temp is not None:
                    self.limits = replace(self.limits, min_extrude_temp_c=min_temp)
            case ObjectDefine(name=name, label=label):
                if label or name not in self.objects:
                    self.objects[name] = label
            case ObjectStart(name=name):
                self.objects.setdefault(name, "")
            case LayerChange(index=index):
                self.layers = max(self.layers, index + 1)
            case _:
                pass
        self._planned(self.planner.command(item))
        if self.free is not None:
            self._free_planned(self.free.command(item))

    def _unexpected(self, line: int, word: str, kind: str, text: str, detail: str) -> None:
        """Unknown commands and ignored parameters: warnings, or errors with ``strict``."""
        if self.strict:
            self.violations.add(line, kind, self.planner.position, detail)
        else:
            self.warnings.add(line, word, kind, text)

    def _chunk(self, chunk: MoveChunk) -> None:
        if not len(chunk):
            return
        self.layers = max(self.layers, int(np.max(chunk.layer)) + 1)
        self.extent.add(chunk)
        block, outputs = self.planner.moves(chunk)
        if len(block):
            self._check_block(block)
        self._planned(outputs)
        if self.free is not None:
            self._free_planned(self.free.moves(chunk)[1])

    def _check_block(self, block: MoveBlock) -> None:
        for f in self.checker.check(block):
            self.violations.add(int(block.line[f.move]), f.rule, f.point, f.detail)
        for rule, n in self.checker.counted.items():
            self.violations.count(rule, n)
        self.checker.counted.clear()
        cold = None if self.cold_allowed else cold_extrusion(block, self.hotend_c, self.limits)
        if cold is not None:
            first, count = cold
            self.violations.add(
                int(block.line[first]),
                "cold_extrusion",
                block.end[first],
                cold_detail(block, first, count, self.hotend_c, self.limits),
            )
        self.motion_box.add(block.end)
        extruding = block.extrusion > 0
        if extruding.any():
            self.print_box.add(block.end[extruding])
            self.print_box.add(block.start[extruding])

    def _planned(self, outputs: list[Any]) -> None:
        for marked in outputs:
            if not isinstance(marked, MarkedMoves):  # a command: checked when it was added
                continue
            out = marked.planned
            if self.free is not None:
                self.axis_time += self._axis_time(out)
            self.slowed += int(np.count_nonzero(out.module_limited))
            flow = volumetric_flow(out, self.limits)
            if flow.size:
                self.max_flow = max(self.max_flow, float(flow.max()))
            for i in np.flatnonzero(flow > self.limits.max_flow_mm3_s):
                self.violations.add(
                    int(out.moves.line[i]),
                    "volumetric_flow",
                    out.moves.end[i],
                    f"melt flow {flow[i]:.3g} mm^3/s at {out.v_cruise[i]:.4g} mm/s exceeds "
                    f"{self.limits.max_flow_mm3_s:g} mm^3/s by {flow[i] - self.limits.max_flow_mm3_s:.3g}",
                )

    def _axis_time(self, planned: Any) -> np.ndarray:
        """(4,) s of ``planned``'s moves by the axis each needs most steps/s on."""
        moves = planned.moves
        axis = busiest_axis(
            moves.start,
            moves.end,
            moves.e_end - moves.e_start,
            self.model.geometry.outlets,
            np.asarray(self.profile.drive.steps_per_mm),
            self.profile.extruder.steps_per_mm,
        )
        return np.bincount(axis, weights=planned.duration, minlength=4)

    def _free_planned(self, outputs: list[Any]) -> None:
        for marked in outputs:
            if isinstance(marked, MarkedMoves):
                self.free_axis_time += self._axis_time(marked.planned)

    def _board(self) -> BoardReport | None:
        """The board the estimate is for, and what it costs (after both planners finished)."""
        if self.device is None:
            return None
        board_s = self.planner.time
        free_s = board_s if self.free is None else self.free.time
        axes = slowed_axes(self.axis_time - self.free_axis_time) if self.free else []
        slows = board_s > free_s * (1.0 + 1e-3)
        return BoardReport(
            max_step_rate=self.device.max_step_rate,
            min_segment_s=self.device.min_segment_s,
            source=self.device_source,
            time_at_profile_limits_s=round(free_s, 3),
            slowed_axes={name: round(share, 3) for name, share in axes},
            message=slowdown_message(
                self.device.max_step_rate, axes, board_s, free_s, self.device.total_step_rate
            )
            if slows
            else "",
        )

    def report(self) -> PreflightReport:
        """The report; raises `GcodeError` (bad input) for a program without moves."""
        if self.summary.moves == 0:
            what = (
                "the file has no commands (it is empty, or only comments and settings)"
                if self.summary.last_line == 0
                else f"only commands up to line {self.summary.last_line}"
            )
            raise GcodeError(self.source, 0, 0, f"no moves, nothing to print: {what}")
        self._planned(self.planner.finish())
        if self.free is not None:
            self._free_planned(self.free.finish())
        origin = self.planner.origin
        return PreflightReport(
            source=self.source,
            profile=self.profile.name,
            ok=self.violations.total == 0,
            violations=self.violations.ordered(),
            violations_total=self.violations.total,
            violations_by_rule=dict(self.violations.counts),
            notes=self.notes.ordered(),
            warnings=self.warnings.ordered(),
            warnings_total=self.warnings.total,
            strict=self.strict,
            objects=list(self.objects),
            object_labels={k: v for k, v in self.objects.items() if v},
            moves=self.summary.moves,
            layers=self.layers,
            filament_mm=round(self.summary.filament_mm, 4),
            filament_fed_mm=round(self.summary.filament_fed_mm, 4),
            estimated_time_s=round(self.planner.time, 3),
            board=self._board(),
            moves_slowed_by_modules=self.slowed,
            moves_sampled_densely=self.checker.sampled_moves,
            motion_box_machine=self.motion_box.box(),
            print_box_gcode=self.print_box.box(origin),
            min_extrude_temp_c=self.limits.min_extrude_temp_c,
            max_volumetric_flow_mm3_s=self.limits.max_flow_mm3_s,
            max_volumetric_flow_seen_mm3_s=round(self.max_flow, 4),
        )


def preflight_items(
    items: Iterable[ProgramItem],
    profile: MachineProfile,
    model: MachineModel | None = None,
    *,
    source: str = "<program>",
    **options: Any,
) -> PreflightReport:
    pf = Preflight(profile, model, source=source, **options)
    for item in items:
        pf.add(item)
    return pf.report()


WORKSPACE_RULES = ("build_volume", "tension", "slider_travel")


def preflight(
    path: str | os.PathLike[str],
    profile: MachineProfile,
    model: MachineModel | None = None,
    *,
    setup: Setup | None = None,
    **options: Any,
) -> PreflightReport:
    """Read and check a G-code file (placed, retargeted, objects cancelled as ``setup``
    says); raises `GcodeError` (exit 2) on malformed input."""
    return preflight_prepared(prepare(path, profile, model, setup), **options)


def preflight_prepared(
    prepared: Prepared, items: Iterable[ProgramItem] | None = None, **options: Any
) -> PreflightReport:
    """Check ``prepared`` (``items``: instead of ``prepared.items()``, e.g. resumed from a
    layer); the report adds the placement, what --retarget replaced and the slicer's figures."""
    pf = Preflight(prepared.profile, prepared.model, source=prepared.path, **options)
    for item in prepared.items() if items is None else items:
        pf.add(item)
    report = pf.report()
    advise = any(report.violations_by_rule.get(rule) for rule in WORKSPACE_RULES)
    report.placement = placement_report(
        prepared.model, pf.extent, pf.planner.origin, prepared.placement, advise=advise
    )
    if prepared.plan is not None:
        plan = prepared.plan
        report.retarget = RetargetReport(
            start_lines=plan.start,
            end_lines=None
            if plan.end is None
            else (plan.end[0], max(plan.end[0], plan.file_lines)),
            found_by=plan.found_by,
            replaced=list(plan.replaced),
            purge_lines=[run.text() for run in plan.purge_lines],
            hotend_c=plan.hotend_c
            if plan.hotend_c is not None
            else prepared.profile.gcode.hotend_c,
            bed_c=plan.bed_c if plan.bed_c is not None else prepared.profile.gcode.bed_c,
        )
    report.cancelled_objects = list(prepared.setup.cancel_objects)
    report.slicer = slicer_figures(prepared.path, prepared.profile)
    return report


def slicer_figures(path: str, profile: MachineProfile) -> SlicerFigures | None:
    """The slicer's own figures from the file's comments; a volume (UltiGCode) in mm of
    this machine's filament."""
    fig = read_slicer_figures(path)
    if fig is None:
        return None
    filament = fig.filament_mm
    if filament is None and fig.filament_mm3 is not None:
        filament = fig.filament_mm3 / (math.pi * profile.extruder.filament_diameter_mm**2 / 4.0)
    return SlicerFigures(
        slicer=fig.slicer,
        filament_mm=None if filament is None else round(filament, 3),
        time_s=fig.time_s,
        exported_profile=fig.exported_profile,
    )
