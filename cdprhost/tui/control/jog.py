"""Jog targets and their feasibility, decided before anything moves (pure)."""

from __future__ import annotations

import numpy as np

from cdprhost.kinematics import MachineModel, tensions
from cdprhost.tui.control.views import JogCheck, Vec3

AXES = {"x": 0, "y": 1, "z": 2}
STEPS_MM = (0.1, 1.0, 10.0, 50.0)


def jog_target(current: Vec3, axis: str, step_mm: float) -> Vec3:
    """``current`` moved by ``step_mm`` along ``axis`` ("x", "y" or "z")."""
    p = [float(v) for v in current]
    p[AXES[axis]] += step_mm
    return (p[0], p[1], p[2])


def check_jog(
    model: MachineModel, start: Vec3 | None, target: Vec3, spacing_mm: float = 1.0
) -> JogCheck:
    """Whether the straight move ``start`` -> ``target`` stays in the workspace.

    The path is sampled every ``spacing_mm`` (and at both ends); the first
    failing sample names the rule. Without a known start only the target is checked.
    """
    end = np.asarray(target, dtype=float)
    if start is None:
        points = end[None, :]
    else:
        a = np.asarray(start, dtype=float)
        n = max(2, int(np.ceil(np.linalg.norm(end - a) / spacing_mm)) + 1)
        points = a + np.linspace(0.0, 1.0, n)[:, None] * (end - a)
    report = model.check(points)
    ok = report.ok
    if ok.all():
        return JogCheck(tuple(end.tolist()), True, "feasible")
    last = len(points) - 1
    i = last if not ok[last] else int(np.argmin(ok))  # the target's own failure comes first
    where = "target" if i == last else f"path at ({', '.join(f'{v:.1f}' for v in points[i])})"
    reason = f"{where}: {report.rule_name(i)}: {report.describe(i, model.limits)}"
    return JogCheck(tuple(end.tolist()), False, reason, target_ok=bool(ok[last]))


def static_tensions(model: MachineModel, point: Vec3 | None) -> tuple[float, float, float] | None:
    """Cable tensions (N) holding the effector at rest at ``point``; None when unknown or singular."""
    if point is None:
        return None
    t = tensions(np.asarray([point], dtype=float), model.geometry.outlets, model.statics)[0]
    return (float(t[0]), float(t[1]), float(t[2])) if np.all(np.isfinite(t)) else None
