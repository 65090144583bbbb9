"""Restarting a program at a layer: the items that rebuild the machine state, then layer N on.

Before layer N, moves are skipped but the state they leave matters: heater targets
and fan are kept (waits included, so the hotend is hot again), one homing is kept
(the effector's position after a failure is unknown), dwells and messages are
dropped. Then the effector lifts straight up to clear the part, travels above the
first point of layer N, and lowers onto it. The filament axis is re-zeroed at the
first kept move so the extruder does not try to replay everything skipped.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from cdprhost.errors import InputError
from cdprhost.gcode import items as g
from cdprhost.gcode.stream import shift_e, travel

CLEARANCE_MM = 5.0


def from_layer(
    items: Iterable[g.ProgramItem],
    layer: int,
    *,
    z_max: float = float("inf"),
    travel_feedrate: float = 50.0,
) -> Iterator[g.ProgramItem]:
    """Items of ``items`` that restart the program at 0-based ``layer``; ``z_max`` caps the
    clearance lift (G-code frame)."""
    skipped_top = -np.inf
    homed = False
    started = False
    e_offset = 0.0
    last_point: np.ndarray | None = None
    for item in items:
        match item:
            case g.MoveChunk() if started:
                yield shift_e(item, e_offset)
            case _ if started:
                yield item
            case g.MoveChunk():
                keep = np.flatnonzero(item.layer >= layer)
                done = item.end if not keep.size else item.end[: keep[0]]
                if len(done):
                    skipped_top = max(skipped_top, float(done[:, 2].max()))
                    last_point = done[-1]
                if not keep.size:
                    continue
                i = int(keep[0])
                first = item.start[i]
                e_offset = float(item.e_start[i])
                if last_point is not None:  # something was printed: go over it, not through it
                    here = last_point
                    safe_z = min(max(skipped_top, float(first[2])) + CLEARANCE_MM, z_max)
                    route = [
                        here,
                        np.array([here[0], here[1], safe_z]),
                        np.array([first[0], first[1], safe_z]),
                        first,
                    ]
                    yield travel(np.asarray(route), 0.0, int(item.line[i]), layer, travel_feedrate)
                yield shift_e(item.take(slice(i, None)), e_offset)
                started = True
            case g.SetTemperature() | g.Fan() | g.ToolSelect() | g.FlowFactor() | g.SpeedFactor():
                yield item
            case g.SetMotionLimits() | g.ColdExtrusion() | g.ObjectDefine():
                yield item
            case g.HomeCommand() if not homed:
                homed = True
                yield item
            case _:
                pass
    if not started:
        raise InputError(
            f"--resume-from-layer {layer}: the program has no moves in layer {layer} or later"
        )
