"""Limits a program asks for (M201, M203, M204, M205, SET_VELOCITY_LIMIT), per move.

A file can slow the machine down, never speed it up: every value here only
lowers the profile's limits (the planner takes the minimum). Per axis values
(M201 acceleration, M203 speed, for X, Y, Z and E) bound a move along its
direction u as ``limit_axis / |u_axis|`` (E: filament per mm of path), as
Marlin does. M204 chooses the acceleration by what a move does: P for moves
that extrude, T for the others, R for extruder-only moves. A corner velocity
(M205 X/Y jerk, Klipper's SQUARE_CORNER_VELOCITY) becomes a junction deviation
the way Klipper converts it, with the profile's acceleration.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from cdprhost.gcode.items import SetMotionLimits
from cdprhost.motion.moves import MIN_MOVE_MM, MoveBlock

_INF = float("inf")
_NO_AXES = (_INF, _INF, _INF, _INF)


@dataclass(frozen=True)
class FileLimits:
    """The program's current limits (inf: none); see the module docstring."""

    axis_accel: tuple[float, float, float, float] = _NO_AXES
    axis_velocity: tuple[float, float, float, float] = _NO_AXES
    print_accel: float = _INF
    travel_accel: float = _INF
    retract_accel: float = _INF
    velocity: float = _INF
    junction_deviation: float = _INF

    @property
    def active(self) -> bool:
        return self != _NONE

    def updated(self, cmd: SetMotionLimits, profile_accel: float) -> FileLimits:
        """These limits after ``cmd`` (values it leaves out stay as they were)."""

        def pick(new: float | None, old: float) -> float:
            return old if new is None else float(new)

        def axes(
            new: tuple[float | None, ...], old: tuple[float, ...]
        ) -> tuple[float, float, float, float]:
            a, b, c, d = (pick(n, o) for n, o in zip(new, old))
            return (a, b, c, d)

        jd = self.junction_deviation
        if cmd.corner_velocity is not None:
            jd = cmd.corner_velocity**2 * (2.0**0.5 - 1.0) / profile_accel
        if cmd.junction_deviation is not None:
            jd = cmd.junction_deviation
        return replace(
            self,
            axis_accel=axes(cmd.axis_accel, self.axis_accel),
            axis_velocity=axes(cmd.axis_velocity, self.axis_velocity),
            print_accel=pick(cmd.print_accel, self.print_accel),
            travel_accel=pick(cmd.travel_accel, self.travel_accel),
            retract_accel=pick(cmd.retract_accel, self.retract_accel),
            velocity=pick(cmd.velocity, self.velocity),
            junction_deviation=jd,
        )


_NONE = FileLimits()


def _axis_bound(limits: tuple[float, ...], components: np.ndarray) -> np.ndarray:
    """min over axes of limit / |component| (inf where a component is 0)."""
    out = np.full(components.shape[0], _INF)
    for k, lim in enumerate(limits):
        if np.isfinite(lim):
            c = np.abs(components[:, k])
            with np.errstate(divide="ignore"):
                out = np.minimum(out, np.where(c > 0, lim / np.where(c > 0, c, 1.0), _INF))
    return out


def apply_file_limits(block: MoveBlock, limits: FileLimits) -> MoveBlock:
    """``block`` with the program's limits: lower feedrates, per-move acceleration and
    junction deviation limits (unchanged when the program set none)."""
    if not len(block) or not limits.active:
        return block
    d = block.delta
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    de = block.extrusion
    kin = dist > MIN_MOVE_MM
    inv = np.where(kin, 1.0 / np.where(kin, dist, 1.0), 0.0)
    # direction components per unit of path: X, Y, Z and filament (E only: 1 along E)
    comp = np.column_stack([d * inv[:, None], np.where(kin, de * inv, np.sign(de))])
    v = np.minimum(_axis_bound(limits.axis_velocity, comp), limits.velocity)
    a = _axis_bound(limits.axis_accel, comp)
    by_kind = np.where(
        kin, np.where(de > 0, limits.print_accel, limits.travel_accel), limits.retract_accel
    )
    a = np.minimum(a, by_kind)
    feed = np.minimum(block.feedrate, v) if np.isfinite(v).any() else block.feedrate
    accel = None if not np.isfinite(a).any() else a
    if block.accel_limit is not None:
        accel = block.accel_limit if accel is None else np.minimum(accel, block.accel_limit)
    junction = None
    if np.isfinite(limits.junction_deviation):
        junction = np.full(len(block), limits.junction_deviation)
    return replace(block, feedrate=feed, accel_limit=accel, junction_limit=junction)
