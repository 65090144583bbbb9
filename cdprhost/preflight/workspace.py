"""Whole-path workspace check of straight moves, fast for the common clean case.

The rules are the model's (tension under a_max, slider travel, build volume). A
move is certified clean without sampling when:
- both endpoints pass (the build volume is convex, so the segment stays inside);
- no slider leaves its travel in between: |B - A_k| is convex along a line, so
  its maximum is at an endpoint, and inside the move it dips below the smaller
  endpoint value by at most d^2 / L (d the move's length); sliders must keep a
  0.5 mm margin beyond that (room for effects that bend the ideal relation);
- tension: once per model, a 5 mm grid with a local Lipschitz bound certifies the
  whole build volume tension-feasible (true for the shipped profiles). Without
  that certificate, endpoint margins g0 + g1 > G d (G bounds the gradient) do.
Every other move is sampled at <= 1 mm spacing with ``model.check`` and the first
failing sample is reported. Points are in the machine frame.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import tension_bounds
from cdprhost.kinematics.workspace import RULES, build_volume_excess, triangle_excess
from cdprhost.motion.moves import MoveBlock

SAMPLE_MM = 1.0
#: sample points checked at once (bounds memory)
MAX_SAMPLES_PER_BATCH = 1 << 18
#: failing moves per rule and batch described in full; the others are counted (`counted`)
DETAILED_PER_RULE = 256
#: sliders closer than this to a travel limit at a checked point send the move to dense sampling
SLIDER_MARGIN_MM = 0.5


@dataclass(frozen=True)
class PathFailure:
    """First failing point of one move."""

    move: int  # index in the checked block
    rule: str
    point: np.ndarray
    detail: str


def _tension_margin(points: np.ndarray, model: MachineModel) -> np.ndarray:
    lo, hi = tension_bounds(points, model.geometry.outlets, model.statics)
    return np.minimum(lo - model.statics.t_min, model.statics.t_max - hi).min(axis=1)


def _certify_grid(model: MachineModel, h: float) -> tuple[bool | None, float]:
    """True: certified; None: undecided at this spacing; False: a grid point inside fails."""
    lim = model.limits
    side, r = lim.build_side, lim.build_side / np.sqrt(3.0)
    spans = (
        (-side / 2, side / 2),
        (-r / 2, r),
        (lim.z_min, lim.z_max),
    )  # the build volume's bounding box
    axes = [np.linspace(a, b, max(int(np.ceil((b - a) / h)), 1) + 1) for a, b in spans]
    steps = np.array([ax[1] - ax[0] for ax in axes])
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    with np.errstate(all="ignore"):
        margin = _tension_margin(grid.reshape(-1, 3), model).reshape(grid.shape[:3])
        grad = np.linalg.norm(np.stack(np.gradient(margin, *steps), axis=-1), axis=-1)
    margin = np.where(np.isfinite(margin), margin, -np.inf)
    grad = np.where(np.isfinite(grad), grad, np.inf)

    def corners(a: np.ndarray, op: np.ufunc) -> np.ndarray:
        sx, sy, sz = (n - 1 for n in a.shape)
        return op.reduce(
            [a[i : sx + i, j : sy + j, k : sz + k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        )

    half_diag = 0.5 * float(np.linalg.norm(steps))
    bound = corners(margin, np.minimum) - 1.5 * corners(grad, np.maximum) * half_diag
    centre = grid[:-1, :-1, :-1, :2] + steps[:2] / 2.0
    touches = triangle_excess(centre.reshape(-1, 2), side).reshape(bound.shape) <= 0.5 * float(
        np.linalg.norm(steps[:2])
    )
    inside = build_volume_excess(grid.reshape(-1, 3), side, lim.z_min, lim.z_max) <= 1e-9
    g_max = float(np.max(grad.reshape(-1)[inside])) * 1.5 if inside.any() else np.inf
    inside = inside.reshape(margin.shape)
    if np.any(margin[inside] <= 0):
        return False, g_max
    return (True if np.all(bound[touches] > 0) else None), g_max


def tension_certificate(
    model: MachineModel, spacings: tuple[float, ...] = (10.0, 5.0, 2.5)
) -> tuple[bool, float]:
    """(whole build volume tension-feasible, gradient bound G of the margin in N/mm).

    Margins on a grid over the build volume's bounding box; a cell counts when its
    smallest corner margin exceeds 1.5 x (largest corner gradient) x (half its
    diagonal). Coarse grids first; finer ones only when a coarse one cannot decide.
    """
    g_max = np.inf
    for h in spacings:
        ok, g_max = _certify_grid(model, h)
        if ok is not None:
            return ok, g_max
    return False, g_max


class PathChecker:
    """Checks blocks of consecutive moves against the workspace along their whole path."""

    def __init__(self, model: MachineModel):
        self.model = model
        self.volume_certified, self.gradient_bound = tension_certificate(model)
        lim = model.limits
        shortest = float(np.min(model.geometry.initial_lengths + lim.travel[:, 0]))
        self.shortest_cable = (
            shortest if shortest > 0 else 0.0
        )  # 0: every move near s_min gets sampled
        self.sampled_moves = 0
        self.counted: Counter[str] = Counter()  # failing moves beyond the detailed ones

    def _volume_excess(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Build-volume excess (<= 0 inside), as ``build_volume_excess`` but column-wise."""
        lim = self.model.limits
        inradius = lim.build_side / (2.0 * np.sqrt(3.0))
        cx, sy = np.sqrt(3.0) / 2.0, 0.5
        tri = np.maximum(np.maximum(-y, cx * x + sy * y), -cx * x + sy * y) - inradius
        return np.maximum(tri, np.maximum(lim.z_min - z, z - lim.z_max))

    def check(self, block: MoveBlock) -> list[PathFailure]:
        n = len(block)
        if n == 0:
            return []
        model, lim = self.model, self.model.limits
        chained = np.array_equal(block.start[1:], block.end[:-1])
        pts = (
            np.vstack([block.start[:1], block.end])
            if chained
            else np.vstack([block.start, block.end])
        )
        i0 = np.arange(n)
        i1 = i0 + 1 if chained else i0 + n
        bv = self._volume_excess(pts[:, 0], pts[:, 1], pts[:, 2])
        s = model.ik(pts)
        lo, hi = lim.travel[:, 0], lim.travel[:, 1]
        room_lo = np.minimum(np.minimum(s[:, 0] - lo[0], s[:, 1] - lo[1]), s[:, 2] - lo[2])
        room_hi = np.minimum(np.minimum(hi[0] - s[:, 0], hi[1] - s[:, 1]), hi[2] - s[:, 2])
        bad_pt = ~(bv <= 0) | ~(room_hi > SLIDER_MARGIN_MM) | ~(room_lo > SLIDER_MARGIN_MM)
        suspect = bad_pt[i0] | bad_pt[i1]
        # |B - A_k| is convex along the move: the far limit holds between passing endpoints; the
        # near one can dip inside by at most d^2 / L (foot of the perpendicular from A_k)
        d = block.delta
        dist2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        dip = dist2 / self.shortest_cable if self.shortest_cable > 0 else np.inf
        suspect |= np.minimum(room_lo[i0], room_lo[i1]) - dip <= SLIDER_MARGIN_MM
        if not self.volume_certified:
            g = _tension_margin(pts, model)
            suspect |= (
                ~(g[i0] > 0)
                | ~(g[i1] > 0)
                | ~(g[i0] + g[i1] > self.gradient_bound * np.sqrt(dist2))
            )
        idx = np.flatnonzero(suspect)
        return self._sample(block, idx) if idx.size else []

    def _exit_fraction(self, start: np.ndarray, end: np.ndarray) -> np.ndarray:
        """Per move, the fraction of its length where it first leaves the build volume
        (0: it starts outside; inf: it never leaves). The volume is an intersection of
        half-spaces, so this is exact."""
        lim = self.model.limits
        inradius = lim.build_side / (2.0 * np.sqrt(3.0))
        cx, sy = np.sqrt(3.0) / 2.0, 0.5
        normals = np.array(
            [[0.0, -1.0, 0.0], [cx, sy, 0.0], [-cx, sy, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]
        )
        offsets = np.array([inradius, inradius, inradius, -lim.z_min, lim.z_max])
        a = start @ normals.T - offsets  # <= 0 inside, per face
        b = (end - start) @ normals.T
        outside = (a > 0).any(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(b > 0, -a / np.where(b > 0, b, 1.0), np.inf)
        return np.where(outside, 0.0, t.min(axis=1))

    def _sample(self, block: MoveBlock, idx: np.ndarray) -> list[PathFailure]:
        """Dense check of the moves ``idx``: the first failing sample of each.

        Samples stop one step past the point where a move leaves the build volume
        (the first failure is there or before), so the cost is bounded by the
        volume's size, whatever the coordinates; they are checked in batches.
        """
        self.sampled_moves += int(idx.size)
        start, end = block.start[idx], block.end[idx]
        steps = np.maximum(np.ceil(block.distance[idx] / SAMPLE_MM), 1.0)
        exit_step = np.floor(self._exit_fraction(start, end) * steps) + 1.0
        count = (np.minimum(steps, exit_step) + 1).astype(np.int64)
        failures: list[PathFailure] = []
        lo = 0
        while lo < idx.size:
            total = np.cumsum(count[lo:])
            hi = lo + max(int(np.searchsorted(total, MAX_SAMPLES_PER_BATCH, side="right")), 1)
            failures += self._sample_batch(block, idx, lo, hi, steps, count)
            lo = hi
        return failures

    def _sample_batch(
        self,
        block: MoveBlock,
        idx: np.ndarray,
        lo: int,
        hi: int,
        steps: np.ndarray,
        count: np.ndarray,
    ) -> list[PathFailure]:
        start, end = block.start[idx[lo:hi]], block.end[idx[lo:hi]]
        cnt = count[lo:hi]
        owner = np.repeat(np.arange(hi - lo), cnt)
        first = np.cumsum(cnt) - cnt
        frac = (np.arange(owner.size) - first[owner]) / steps[lo:hi][owner]
        pts = start[owner] + frac[:, None] * (end - start)[owner]
        report = self.model.check(pts)
        bad = np.flatnonzero(~report.ok)
        if not bad.size:
            return []
        # per failing move: its first failing sample, and the worst sample of that rule
        owners, first_bad = np.unique(owner[bad], return_index=True)
        first = bad[first_bad]
        rule = report.rule[first]
        same = bad[report.rule[bad] == rule[np.searchsorted(owners, owner[bad])]]
        key = np.lexsort((-report.excess[same], owner[same]))  # by owner, worst first
        ordered = same[key]
        starts = np.flatnonzero(np.r_[True, owner[ordered][1:] != owner[ordered][:-1]])
        worst = ordered[starts]
        # details for the first moves of each rule; the others are only counted
        rank = np.zeros(rule.size, dtype=np.int64)
        for r in np.unique(rule).tolist():
            sel = rule == r
            rank[sel] = np.arange(int(sel.sum()))
        detailed = rank < DETAILED_PER_RULE
        for r, n in zip(*np.unique(rule[~detailed], return_counts=True)):
            self.counted[RULES[int(r)]] += int(n)
        failures = []
        lim = self.model.limits
        for k in np.flatnonzero(detailed).tolist():
            o, i, w = int(owners[k]), int(first[k]), int(worst[k])
            worst_point, detail = pts[w], report.describe(w, lim)
            if report.rule_name(i) == "build_volume":  # convex: the worst is an end point
                ends = np.vstack([start[o], end[o]])
                excess = build_volume_excess(ends, lim.build_side, lim.z_min, lim.z_max)
                if excess.max() > report.excess[w]:
                    worst_point = ends[int(np.argmax(excess))]
                    detail = f"outside the build volume by {excess.max():.3g} mm"
            if not np.array_equal(worst_point, pts[i]):
                detail += " at worst, at ({:.2f}, {:.2f}, {:.2f}); it first fails here".format(
                    *worst_point
                )
            failures.append(
                PathFailure(int(idx[lo + o]), str(report.rule_name(i)), pts[i].copy(), detail)
            )
        return failures
