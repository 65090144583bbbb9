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
from dataclasses import replace
from typing import Any

import numpy as np

from cdprhost.errors import InputError
from cdprhost.gcode import items as g

CLEARANCE_MM = 5.0


def _travel_chunk(
    points: list[np.ndarray], e: float, line: int, layer: int, feedrate: float
) -> g.MoveChunk:
    pts = np.asarray(points, dtype=float)
    n = len(pts) - 1
    return g.MoveChunk(
        start=pts[:-1].copy(),
        end=pts[1:].copy(),
        e_start=np.full(n, e),
        e_end=np.full(n, e),
        feedrate=np.full(n, feedrate),
        line=np.full(n, line, dtype=np.int64),
        layer=np.full(n, layer, dtype=np.int32),
        kind=np.full(n, int(g.MoveKind.TRAVEL), dtype=np.uint8),
        rapid=np.ones(n, dtype=bool),
    )


def from_layer(
    items: Iterable[Any], layer: int, *, z_max: float = float("inf"), travel_feedrate: float = 50.0
) -> Iterator[Any]:
    """Items of ``items`` that restart the program at 0-based ``layer``; ``z_max`` caps the
    clearance lift (G-code frame)."""
    skipped_top = -np.inf
    homed = False
    started = False
    e_offset = 0.0
    last_point: np.ndarray | None = None
    for item in items:
        if started:
            if isinstance(item, g.MoveChunk):
                yield replace(item, e_start=item.e_start - e_offset, e_end=item.e_end - e_offset)
            else:
                yield item
            continue
        if isinstance(item, g.MoveChunk):
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
                yield _travel_chunk(route, 0.0, int(item.line[i]), layer, travel_feedrate)
            rest = np.arange(i, len(item.line))
            yield replace(
                item,
                start=item.start[rest],
                end=item.end[rest],
                e_start=item.e_start[rest] - e_offset,
                e_end=item.e_end[rest] - e_offset,
                feedrate=item.feedrate[rest],
                line=item.line[rest],
                layer=item.layer[rest],
                kind=item.kind[rest],
                rapid=item.rapid[rest],
            )
            started = True
        elif isinstance(item, (g.SetTemperature, g.Fan, g.ToolSelect)):
            yield item
        elif isinstance(item, g.Home) and not homed:
            homed = True
            yield item
    if not started:
        raise InputError(
            f"--resume-from-layer {layer}: the program has no moves in layer {layer} or later"
        )
