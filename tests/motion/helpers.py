"""Small helpers for the motion tests: build move blocks and run the planner on them."""

from __future__ import annotations

import numpy as np

from cdprhost.motion.limits import Caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.planner import Planner
from cdprhost.motion.segments import PlannedSegments, Segmenter
from cdprhost.motion.trapezoid import PlannedMoves


def path_block(points, feedrate=100.0, e_per_mm=0.0, e0=0.0) -> MoveBlock:
    """Moves through ``points`` (machine frame), extruding ``e_per_mm`` per mm of path."""
    p = np.asarray(points, dtype=float)
    start, end = p[:-1], p[1:]
    dist = np.linalg.norm(end - start, axis=1)
    e = e0 + np.concatenate([[0.0], np.cumsum(dist * e_per_mm)])
    return MoveBlock.from_arrays(start, end, e[:-1], e[1:], feedrate)


def caps_for(profile, *, module_limits=True) -> Caps:
    return Caps.from_profile(
        profile.motion, profile.extruder, profile.statics.a_max_mm_s2, module_limits=module_limits
    )


def plan_all(
    block: MoveBlock, profile, model, *, pieces: int = 1, **options
) -> tuple[list[PlannedMoves], Planner]:
    """Plan a block pushed in ``pieces`` parts, flushed at the end."""
    planner = Planner(
        caps_for(profile, module_limits=options.pop("module_limits", True)),
        model.geometry.outlets,
        **options,
    )
    out: list[PlannedMoves] = []
    bounds = np.linspace(0, len(block), pieces + 1).astype(int)
    for a, b in zip(bounds[:-1], bounds[1:]):
        out += planner.push(block.take(slice(a, b)))
    out += planner.flush()
    return out, planner


def concat_planned(parts: list[PlannedMoves]) -> dict[str, np.ndarray]:
    keys = ("length", "accel", "v_start", "v_cruise", "v_end", "t_start")
    return {k: np.concatenate([getattr(p, k) for p in parts]) for k in keys} | {
        "duration": np.concatenate([p.duration for p in parts]),
        "line": np.concatenate([p.moves.line for p in parts]),
    }


def segment_all(
    parts: list[PlannedMoves], profile, model, start_point=None
) -> tuple[list[PlannedSegments], Segmenter]:
    seg = Segmenter(model, profile.drive.home_mm, e_steps_per_mm=profile.extruder.steps_per_mm)
    if start_point is not None:
        from dataclasses import replace

        s = model.ik(np.asarray(start_point, float)[None, :])
        steps = np.append(model.steps(s)[0], 0)
        seg.state = replace(seg.state, steps=steps, point=np.asarray(start_point, float))
    return [seg(p) for p in parts], seg


def concat_batches(batches: list[PlannedSegments]) -> dict[str, np.ndarray]:
    keys = (
        "steps_abs",
        "delta",
        "ticks",
        "ramp",
        "v_start",
        "v_end",
        "line",
        "point",
        "e",
        "t_end",
    )
    return {k: np.concatenate([getattr(b, k) for b in batches]) for k in keys}


def triangle_corners(side=170.0 * 0.9):
    r = side / np.sqrt(3.0)
    return np.array([[0.0, r], [-side / 2, -r / 2], [side / 2, -r / 2]])
