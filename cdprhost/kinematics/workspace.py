"""Workspace membership with the failed rule named (spec: "Workspace").

Rules, checked in this order for every point:
1. ``tension``: every cable stays within [T_min, T_max] for any |a| <= a_max;
2. ``slider_travel``: s_min_k <= s_k <= s_max_k (commanded, effects included);
3. ``build_volume``: inside the equilateral build triangle and z_min <= z <= z_max.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.kinematics.statics import StaticsParams, tension_bounds

RULES = ("tension", "slider_travel", "build_volume")
OK = -1


@dataclass(frozen=True)
class WorkspaceLimits:
    outlets: np.ndarray
    statics: StaticsParams
    travel: np.ndarray  # (3, 2) [s_min, s_max]
    build_side: float
    z_min: float
    z_max: float


@dataclass(frozen=True)
class WorkspaceReport:
    """Per point: ``rule`` index into RULES of the first failed rule (or -1), its
    ``excess`` (how far past the limit, in the rule's unit) and ``detail`` inputs."""

    rule: np.ndarray  # (N,) int8
    excess: np.ndarray  # (N,) float
    cable: np.ndarray  # (N,) int8: offending cable/module (0-based) or -1

    @property
    def ok(self) -> np.ndarray:
        return self.rule == OK

    def rule_name(self, i: int) -> str | None:
        r = int(self.rule[i])
        return None if r == OK else RULES[r]

    def describe(self, i: int, limits: WorkspaceLimits) -> str:
        r, ex, k = int(self.rule[i]), float(self.excess[i]), int(self.cable[i])
        if r == 0:
            return f"cable {k + 1} tension leaves [{limits.statics.t_min:g}, {limits.statics.t_max:g}] N by {ex:.3g} N under |a| <= {limits.statics.a_max:g} mm/s^2"
        if r == 1:
            lo, hi = limits.travel[k]
            return f"module {k + 1} slider leaves its travel [{lo:g}, {hi:g}] mm by {ex:.3g} mm"
        if r == 2:
            return f"outside the build volume by {ex:.3g} mm"
        return "inside the workspace"


def triangle_excess(xy: np.ndarray, side: float) -> np.ndarray:
    """Signed distance outside the build triangle (<= 0 inside), vertex on +y."""
    inradius = side / (2.0 * np.sqrt(3.0))
    angles = np.deg2rad([270.0, 30.0, 150.0])  # outward edge normals
    normals = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return (np.asarray(xy, dtype=float) @ normals.T).max(axis=1) - inradius


def build_volume_excess(points: np.ndarray, side: float, z_min: float, z_max: float) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    z_ex = np.maximum(z_min - p[:, 2], p[:, 2] - z_max)
    return np.maximum(triangle_excess(p[:, :2], side), z_ex)


def check_workspace(
    points: np.ndarray, sliders: np.ndarray, limits: WorkspaceLimits
) -> WorkspaceReport:
    """Vectorised membership test; ``sliders`` are the commanded displacements at ``points``."""
    p = np.asarray(points, dtype=float)
    n = p.shape[0]
    rule = np.full(n, OK, dtype=np.int8)
    excess = np.zeros(n)
    cable = np.full(n, -1, dtype=np.int8)

    def mark(bad_amount: np.ndarray, which: np.ndarray | None, code: int) -> None:
        bad = (bad_amount > 0) & (rule == OK)
        rule[bad] = code
        excess[bad] = bad_amount[bad]
        if which is not None:
            cable[bad] = which[bad]

    lo, hi = tension_bounds(p, limits.outlets, limits.statics)
    t_ex = np.maximum(limits.statics.t_min - lo, hi - limits.statics.t_max)
    t_ex = np.where(np.isfinite(t_ex), t_ex, np.inf)  # singular configurations fail
    mark(t_ex.max(axis=1), t_ex.argmax(axis=1), 0)

    s = np.asarray(sliders, dtype=float)
    s_ex = np.maximum(limits.travel[:, 0] - s, s - limits.travel[:, 1])
    s_ex = np.where(np.isfinite(s_ex), s_ex, np.inf)
    mark(s_ex.max(axis=1), s_ex.argmax(axis=1), 1)

    mark(build_volume_excess(p, limits.build_side, limits.z_min, limits.z_max), None, 2)
    return WorkspaceReport(rule, excess, cable)
