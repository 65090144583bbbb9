"""Moves the firmware makes on its own: G10/G11 retraction and the M600 park.

They are generated from the reader's state as ordinary `MoveChunk` records, so
planning, preflight and printing treat them like any other move. Firmware
retraction moves the machine E axis only (``ModalState.e_machine``): the file's
own E coordinates are untouched, as in Marlin and Klipper.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cdprhost.gcode.items import FilamentChange, MoveChunk, ProgramItem
from cdprhost.gcode.segment import classify
from cdprhost.gcode.state import ModalState

Point = tuple[float, float, float, float]  # x, y, z, machine e


def here(st: ModalState) -> Point:
    return (float(st.pos[0]), float(st.pos[1]), float(st.pos[2]), st.e_machine)


def chunk_through(
    start: Point, points: list[Point], feeds: list[float], line: int, layer: int
) -> MoveChunk | None:
    """Moves from ``start`` through ``points``; None when nothing moves."""
    track = np.array([start, *points], dtype=float)
    before, after = track[:-1], track[1:]
    kind = classify(before, after)
    keep = np.flatnonzero(kind != 255)
    if not keep.size:
        return None
    n = keep.size
    chunk = MoveChunk(
        start=before[keep, :3],
        end=after[keep, :3],
        e_start=before[keep, 3],
        e_end=after[keep, 3],
        feedrate=np.asarray(feeds, dtype=float)[keep],
        line=np.full(n, line, dtype=np.int64),
        layer=np.full(n, layer, dtype=np.int32),
        kind=kind[keep],
        rapid=np.zeros(n, dtype=bool),
    )
    for f in ("start", "end", "e_start", "e_end", "feedrate", "line", "layer", "kind", "rapid"):
        getattr(chunk, f).flags.writeable = False
    return chunk


def retract(st: ModalState, line: int) -> list[ProgramItem]:
    """G10: pull the filament back (once: a second G10 does nothing, as in firmware)."""
    r = st.retraction
    if st.retracted or r.length_mm <= 0:
        st.retracted = True
        return []
    x, y, z = (float(v) for v in st.pos[:3])
    chunk = chunk_through(
        here(st), [(x, y, z, st.e_machine - r.length_mm)], [r.speed_mm_s], line, st.layer
    )
    st.e_machine -= r.length_mm
    st.retracted = True
    return [chunk] if chunk is not None else []


def unretract(st: ModalState, line: int) -> list[ProgramItem]:
    """G11: push back what G10 pulled, plus the extra length."""
    r = st.retraction
    if not st.retracted:
        return []
    st.retracted = False
    amount = r.length_mm + r.extra_mm
    if amount <= 0:
        return []
    x, y, z = (float(v) for v in st.pos[:3])
    chunk = chunk_through(
        here(st), [(x, y, z, st.e_machine + amount)], [r.unretract_speed_mm_s], line, st.layer
    )
    st.e_machine += amount
    return [chunk] if chunk is not None else []


def filament_change(
    st: ModalState,
    line: int,
    *,
    xy: tuple[float | None, float | None] = (None, None),
    lift_mm: float | None = None,
    retract_mm: float | None = None,
) -> list[ProgramItem]:
    """M600: retract, lift, travel to the park point; wait (`FilamentChange`); come back.

    ``xy`` (G-code coordinates of the file), ``lift_mm`` and ``retract_mm`` override the
    profile's park settings (M600 X Y Z E). Without park settings only the wait remains.
    """
    park = st.park
    if park is None:
        return [FilamentChange(line)]
    park = replace(
        park,
        lift_mm=park.lift_mm if lift_mm is None else lift_mm,
        retract_mm=park.retract_mm if retract_mm is None else retract_mm,
    )
    px = park.xy[0] if xy[0] is None else xy[0] * st.scale + float(st.off[0])
    py = park.xy[1] if xy[1] is None else xy[1] * st.scale + float(st.off[1])
    x, y, z = (float(v) for v in st.pos[:3])
    e = st.e_machine
    r = 0.0 if st.retracted else max(park.retract_mm, 0.0)
    top = max(min(z + max(park.lift_mm, 0.0), park.z_max), z)
    out: list[ProgramItem] = []
    go = chunk_through(
        here(st),
        [(x, y, z, e - r), (x, y, top, e - r), (px, py, top, e - r)],
        [park.retract_speed_mm_s, park.speed_mm_s, park.speed_mm_s],
        line,
        st.layer,
    )
    if go is not None:
        out.append(go)
    out.append(FilamentChange(line))
    back = chunk_through(
        (px, py, top, e - r),
        [(x, y, top, e - r), (x, y, z, e - r), (x, y, z, e)],
        [park.speed_mm_s, park.speed_mm_s, park.retract_speed_mm_s],
        line,
        st.layer,
    )
    if back is not None:
        out.append(back)
    return out
