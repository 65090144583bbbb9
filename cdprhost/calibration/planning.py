"""Measurement-pose planning: candidates, optimal design by exchange, visiting order.

The identification Jacobian J0 maps the 12 parameter errors to the position error
at a pose (dB = J0 dq), so with mocap noise sigma per coordinate the information of
a pose set is sum_i J0_i^T J0_i / sigma^2. Columns are scaled by their RMS over
the candidate set, which makes the singular values dimensionless and the indices
comparable between pose sets; D-optimality does not depend on that scaling.

Observability indices of the scaled Jacobian (L = 12 parameters, m = poses):
O1 = (prod sigma_i)^(1/L) / sqrt(m), O2 = sigma_min / sigma_max, O3 = sigma_min,
O4 = sigma_min^2 / sigma_max, O5 = 1 / sum(1 / sigma_i). ``D`` = log det(J^T J).
``I`` = minus the mean prediction variance trace(W M^-1) over the candidates
(what a workspace-wide validation measures).

The design is found by Fedorov exchange (every swap of a chosen pose for a
candidate evaluated at once, best swap applied, until none improves) from several
random starts and from the greedy design.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdprhost.calibration.commanding import commanded_path
from cdprhost.kinematics.jacobian import identification_jacobian
from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import tension_bounds
from cdprhost.kinematics.workspace import triangle_excess

#: The paper's Table 1 poses (mm), all at z = 110.
TABLE1_POSES = np.array(
    [
        (-30.2310, 24.5370, 110.0),
        (-42.5000, 24.5370, 110.0),
        (-31.8320, 43.0150, 110.0),
        (-36.3660, 13.9120, 110.0),
    ]
)
CRITERIA = ("D", "I", "O1", "O2", "O3", "O4", "O5")
INDEX_NAMES = ("O1", "O2", "O3", "O4", "O5")


# ------------------------------------------------------------------ candidates
def candidate_poses(
    model: MachineModel,
    *,
    spacing_mm: float = 12.0,
    height_step_mm: float = 12.0,
    edge_margin_mm: float = 1.0,
    tension_margin_n: float = 2.0,
    tension_max_fraction: float = 0.9,
    approach_mm: float = 5.0,
    prior_mm: float = 3.0,
    clearance_mm: float = 10.0,
) -> np.ndarray:
    """Hexagonal grid points over the build triangle every ``height_step_mm``, (N, 3).

    Kept where the pose and its approach point ``approach_mm`` above pass every
    workspace rule, the worst-case tensions under a_max stay within
    [T_min + margin, fraction * T_max], and the pose is safe to command before
    calibration (:func:`robust_to_prior`).
    """
    lim = model.limits
    side = lim.build_side
    z_top = lim.z_max - approach_mm
    heights = np.linspace(
        lim.z_min, z_top, max(2, int(np.ceil((z_top - lim.z_min) / height_step_mm)) + 1)
    )
    xs = np.arange(-side / 2, side / 2 + 1e-9, spacing_mm)
    ys = np.arange(-side / (2 * np.sqrt(3)), side / np.sqrt(3) + 1e-9, spacing_mm * np.sqrt(3) / 2)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    gx = gx + (np.arange(ys.size)[None, :] % 2) * spacing_mm / 2  # hexagonal lattice
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    xy = xy[triangle_excess(xy, side) <= -edge_margin_mm]
    pts = np.column_stack([np.tile(xy, (heights.size, 1)), np.repeat(heights, xy.shape[0])])
    ok = feasible_with_margin(model, pts, tension_margin_n, tension_max_fraction, approach_mm)
    return np.asarray(pts[ok & robust_to_prior(model, pts, prior_mm, clearance_mm)])


def robust_to_prior(
    model: MachineModel, points: np.ndarray, prior_mm: float = 3.0, clearance_mm: float = 10.0
) -> np.ndarray:
    """Mask of poses the uncalibrated machine can be commanded to safely.

    Each parameter is only known to +-``prior_mm`` (uniform), so the effector
    really goes ``dB = J0 dq`` off the commanded pose; near the outlets' plane
    dz is ~10x the parameter error. Keep poses whose 3-sigma low point stays
    ``clearance_mm`` above the highest outlet.
    """
    pts = np.asarray(points, dtype=float)
    j0 = identification_jacobian(pts, model.geometry).reshape(-1, 3, 12)
    dz3 = 3.0 * prior_mm / np.sqrt(3.0) * np.linalg.norm(j0[:, 2, :], axis=1)
    return np.asarray(pts[:, 2] - dz3 - model.geometry.outlets[:, 2].max() >= clearance_mm)


def feasible_with_margin(
    model: MachineModel,
    points: np.ndarray,
    tension_margin_n: float = 2.0,
    tension_max_fraction: float = 0.9,
    approach_mm: float = 5.0,
) -> np.ndarray:
    """Mask of poses whose approach point is reachable and whose tensions keep a margin."""
    pts = np.asarray(points, dtype=float)
    above = pts + np.array([0.0, 0.0, approach_mm])
    ok = model.check(pts).ok & model.check(above).ok
    st = model.statics
    lo, hi = tension_bounds(pts, model.geometry.outlets, st)
    ok &= (lo.min(axis=1) >= st.t_min + tension_margin_n) & (
        hi.max(axis=1) <= tension_max_fraction * st.t_max
    )
    return np.asarray(ok)


# ------------------------------------------------------------------ information
def pose_blocks(
    model: MachineModel, points: np.ndarray, scale: np.ndarray | None = None
) -> np.ndarray:
    """Column-scaled J0 blocks (N, 3, 12); ``scale`` defaults to the RMS column norm over ``points``."""
    j0 = identification_jacobian(np.asarray(points, float), model.geometry).reshape(-1, 3, 12)
    if scale is None:
        scale = column_scale(j0)
    return np.asarray(j0 / scale)


def column_scale(blocks: np.ndarray) -> np.ndarray:
    """Per-pose RMS norm of each of the 12 columns, (12,)."""
    return np.asarray(np.sqrt(np.einsum("nij,nij->j", blocks, blocks) / blocks.shape[0]))


def information(blocks: np.ndarray) -> np.ndarray:
    """Per-pose information matrices J_i^T J_i, (N, 12, 12)."""
    return np.asarray(np.einsum("nij,nik->njk", blocks, blocks))


def observability_indices(blocks: np.ndarray) -> dict[str, float]:
    """O1..O5 of the stacked scaled Jacobian of a pose set (blocks (K, 3, 12))."""
    sv = np.linalg.svd(blocks.reshape(-1, blocks.shape[-1]), compute_uv=False)
    return _indices_from_sv(sv, blocks.shape[0])


def _indices_from_sv(sv: np.ndarray, m: int) -> dict[str, float]:
    sv = np.sort(np.asarray(sv, float))[::-1]
    smin, smax = float(sv[-1]), float(sv[0])
    with np.errstate(divide="ignore"):
        o1 = float(np.exp(np.mean(np.log(sv)))) / np.sqrt(m) if smin > 0 else 0.0
        o5 = float(1.0 / np.sum(1.0 / sv)) if smin > 0 else 0.0
    return {"O1": o1, "O2": smin / smax, "O3": smin, "O4": smin * smin / smax, "O5": o5}


def criterion_values(
    info: np.ndarray, criterion: str, m: int, weight: np.ndarray | None = None
) -> np.ndarray:
    """Criterion (larger is better) of stacked information matrices (..., 12, 12)."""
    lam = np.clip(np.linalg.eigvalsh(info), 0.0, None)  # ascending; sigma^2
    if criterion in ("D", "O1"):
        with np.errstate(divide="ignore"):
            logdet = np.sum(np.log(lam), axis=-1)
        return np.asarray(
            logdet if criterion == "D" else np.exp(logdet / (2 * lam.shape[-1])) / np.sqrt(m)
        )
    sv = np.sqrt(lam)
    smin, smax = sv[..., 0], sv[..., -1]
    if criterion == "O2":
        return np.asarray(smin / smax)
    if criterion == "O3":
        return np.asarray(smin)
    if criterion == "O4":
        return np.asarray(smin * smin / smax)
    if criterion == "O5":
        with np.errstate(divide="ignore"):
            return np.where(smin > 0, 1.0 / np.sum(1.0 / np.where(sv > 0, sv, 1.0), axis=-1), 0.0)
    if criterion == "I":
        if weight is None:
            raise ValueError("criterion I needs the mean candidate information as weight")
        reg = info + 1e-12 * np.eye(info.shape[-1])
        with np.errstate(invalid="ignore"):
            trace = np.einsum(
                "...ii->...", np.linalg.solve(reg, np.broadcast_to(weight, reg.shape))
            )
        return np.where(lam[..., 0] > 1e-12, -trace, -np.inf)
    raise ValueError(f"unknown criterion {criterion!r} (known: {', '.join(CRITERIA)})")


# ------------------------------------------------------------------ designs
def greedy_design(
    info: np.ndarray, k: int, criterion: str = "D", weight: np.ndarray | None = None
) -> np.ndarray:
    """Forward selection: add the candidate that best improves the (ridged) criterion."""
    ridge = 1e-6 * np.trace(info.mean(axis=0)) / info.shape[-1] * np.eye(info.shape[-1])
    chosen: list[int] = []
    total = ridge.copy()
    for _ in range(k):
        vals = criterion_values(total + info, criterion, len(chosen) + 1, weight)
        vals[chosen] = -np.inf
        best = int(np.argmax(vals))
        chosen.append(best)
        total += info[best]
    return np.array(chosen)


def _swap_logdet_gain(
    design_blocks: np.ndarray, cand_blocks: np.ndarray, minv: np.ndarray
) -> np.ndarray:
    """log det change of swapping design pose i for candidate j, (k, c), by the
    determinant lemma: det(M - X_i^T X_i + X_j^T X_j) / det M = det of a 6x6 matrix."""
    xi, xj = design_blocks @ minv, cand_blocks @ minv
    b = xi @ design_blocks.transpose(0, 2, 1)  # (k, 3, 3)
    a = xj @ cand_blocks.transpose(0, 2, 1)  # (c, 3, 3)
    cross = np.einsum("iap,jbp->ijab", xi, cand_blocks)  # X_i M^-1 X_j^T, (k, c, 3, 3)
    k, c = b.shape[0], a.shape[0]
    eye = np.eye(3)
    mat = np.empty((k, c, 6, 6))
    mat[..., :3, :3] = (eye - b)[:, None]
    mat[..., :3, 3:] = -cross
    mat[..., 3:, :3] = cross.transpose(0, 1, 3, 2)
    mat[..., 3:, 3:] = (eye + a)[None]
    sign, logdet = np.linalg.slogdet(mat)
    return np.where(sign > 0, logdet, -np.inf)


def fedorov_exchange(
    info: np.ndarray,
    start: np.ndarray,
    criterion: str = "D",
    weight: np.ndarray | None = None,
    *,
    blocks: np.ndarray | None = None,
    max_iter: int = 200,
    rel_tol: float = 1e-9,
    chunk: int = 4096,
) -> tuple[np.ndarray, float]:
    """Best-swap exchange from ``start`` until no swap improves; returns (indices, value).

    With ``blocks`` (the scaled J0 blocks behind ``info``) the D criterion uses
    determinant-lemma updates instead of full eigen-decompositions."""
    design = np.array(start, dtype=int)
    k = design.size
    total = info[design].sum(axis=0)
    value = float(criterion_values(total, criterion, k, weight))
    fast = criterion == "D" and blocks is not None and np.isfinite(value)
    for _ in range(max_iter):
        best = (value, -1, -1)
        minv = np.linalg.inv(total) if fast else None
        for lo in range(0, info.shape[0], chunk):
            cand = info[lo : lo + chunk]
            if fast:
                assert blocks is not None and minv is not None
                vals = value + _swap_logdet_gain(blocks[design], blocks[lo : lo + chunk], minv)
            else:
                trial = total[None, None] - info[design][:, None] + cand[None, :]  # (k, c, 12, 12)
                vals = criterion_values(trial, criterion, k, weight)
            vals[:, np.isin(np.arange(lo, lo + cand.shape[0]), design)] = -np.inf
            i, j = np.unravel_index(int(np.argmax(vals)), vals.shape)
            if vals[i, j] > best[0]:
                best = (float(vals[i, j]), int(i), int(lo + j))
        if best[1] < 0 or best[0] - value <= rel_tol * max(abs(value), 1e-300):
            break
        value, bi, bj = best
        total = total - info[design[bi]] + info[bj]
        design[bi] = bj
    return design, value


@dataclass(frozen=True)
class Design:
    indices: np.ndarray  # into the candidate array
    value: float
    start_values: tuple[float, ...] = field(default=())  # criterion after each restart


def optimal_design(
    info: np.ndarray,
    k: int,
    criterion: str = "D",
    *,
    restarts: int = 8,
    rng: np.random.Generator | None = None,
    weight: np.ndarray | None = None,
    blocks: np.ndarray | None = None,
) -> Design:
    """Fedorov exchange from the greedy design and ``restarts`` random starts; best result."""
    rng = rng or np.random.default_rng(0)
    if weight is None and criterion == "I":
        weight = info.mean(axis=0)
    if k > info.shape[0]:
        raise ValueError(f"asked for {k} poses but only {info.shape[0]} candidates are feasible")
    search = "D" if criterion == "O1" else criterion  # O1 is a monotone function of det at fixed k
    starts = [greedy_design(info, k, search, weight)] + [
        rng.choice(info.shape[0], k, replace=False) for _ in range(restarts)
    ]
    results = [fedorov_exchange(info, s, search, weight, blocks=blocks) for s in starts]
    values = tuple(v for _, v in results)
    best = int(np.argmax(values))
    indices = np.sort(results[best][0])
    value = (
        values[best]
        if search == criterion
        else float(criterion_values(info[indices].sum(axis=0), criterion, k))
    )
    return Design(indices, value, values)


# ------------------------------------------------------------------ check poses
def check_poses(info: np.ndarray, design: np.ndarray, n: int) -> np.ndarray:
    """Candidates where the design predicts worst (largest variance), spread by
    adding each chosen one to the design before picking the next."""
    total = info[design].sum(axis=0)
    chosen: list[int] = []
    for _ in range(n):
        inv = np.linalg.pinv(total)
        var = np.einsum("nii->n", inv[None] @ info)  # trace(M^-1 G_j)
        var[np.concatenate([design, chosen]).astype(int)] = -np.inf
        j = int(np.argmax(var))
        chosen.append(j)
        total = total + info[j]
    return np.array(chosen, dtype=int)


# ------------------------------------------------------------------ visiting order
def tour_length(points: np.ndarray, start: np.ndarray) -> float:
    path = np.vstack([np.asarray(start, float).reshape(1, 3), points])
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def visiting_order(points: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Open tour from ``start`` through every point: nearest neighbour, then 2-opt."""
    pts = np.asarray(points, float)
    n = pts.shape[0]
    if n <= 1:
        return np.arange(n)
    nodes = np.vstack([np.asarray(start, float).reshape(1, 3), pts])
    dist = np.linalg.norm(nodes[:, None] - nodes[None], axis=-1)
    order = [0]
    left = set(range(1, n + 1))
    while left:
        nxt = min(left, key=lambda j: dist[order[-1], j])
        order.append(nxt)
        left.remove(nxt)
    route = np.array(order)
    improved = True
    while improved:  # 2-opt on an open path with a fixed start (small n: at most tens of poses)
        improved = False
        for i in range(1, n):
            a, b = route[i - 1], route[i]
            c = route[i:]
            d_next = np.append(route[i + 1 :], -1)
            old = dist[a, b] + np.where(d_next >= 0, dist[c, np.maximum(d_next, 0)], 0.0)
            new = dist[a, c] + np.where(d_next >= 0, dist[b, np.maximum(d_next, 0)], 0.0)
            gain = old - new
            gain[0] = 0.0
            j = int(np.argmax(gain))
            if gain[j] > 1e-9:
                route[i : i + j + 1] = route[i : i + j + 1][::-1]
                improved = True
    return route[1:] - 1


# ------------------------------------------------------------------ the plan
@dataclass(frozen=True)
class PosePlan:
    """Poses in visiting order with their role, approach point and approach directions."""

    poses: np.ndarray  # (K, 3)
    roles: tuple[str, ...]  # "fit" | "check"
    approach: np.ndarray  # (K, 3): the point each pose is approached from
    directions: np.ndarray  # (K, 3): sign of each module's last motion into the pose
    criterion: str
    indices: dict[str, float]  # O1..O5 of the fit poses
    table1_indices: dict[str, float]
    value: float
    n_candidates: int
    travel_mm: float
    rounds: tuple[int, ...] = ()  # per pose: 0 planned, n added by the n-th augmentation

    def round_of(self, i: int) -> int:
        return self.rounds[i] if i < len(self.rounds) else 0

    @property
    def fit_poses(self) -> np.ndarray:
        return np.asarray(self.poses[np.array(self.roles) == "fit"])


def plan_poses(
    model: MachineModel,
    n_poses: int = 4,
    *,
    n_check: int = 0,
    criterion: str = "D",
    restarts: int = 8,
    approach_mm: float = 5.0,
    seed: int = 0,
    candidates: np.ndarray | None = None,
) -> PosePlan:
    """Plan ``n_poses`` fit poses (plus ``n_check`` check poses) over the whole workspace."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown criterion {criterion!r} (known: {', '.join(CRITERIA)})")
    if n_poses < 4:
        raise ValueError(
            "at least 4 poses are needed to identify 12 parameters (3 equations per pose)"
        )
    cand = (
        candidate_poses(model, approach_mm=approach_mm)
        if candidates is None
        else np.asarray(candidates, float)
    )
    j0 = identification_jacobian(cand, model.geometry).reshape(-1, 3, 12)
    scale = column_scale(j0)
    blocks = j0 / scale
    info = information(blocks)
    design = optimal_design(
        info, n_poses, criterion, restarts=restarts, rng=np.random.default_rng(seed), blocks=blocks
    )
    checks = check_poses(info, design.indices, n_check) if n_check else np.zeros(0, int)
    chosen = np.concatenate([design.indices, checks])
    roles = np.array(["fit"] * design.indices.size + ["check"] * checks.size)
    home = model.home_point(np.zeros(3))
    order = visiting_order(cand[chosen], home)
    poses = cand[chosen][order]
    approach = poses + np.array([0.0, 0.0, approach_mm])
    # Each pose is reached by a straight descent from its approach point, so every
    # module's last motion shortens its cable: directions are -1 throughout.
    waypoints = np.empty((2 * len(poses), 3))
    waypoints[0::2], waypoints[1::2] = approach, poses
    _, dirs = commanded_path(model, waypoints, start_sliders=model.ik(home[None])[0])
    table1 = pose_blocks(model, TABLE1_POSES, scale)
    return PosePlan(
        poses=poses,
        roles=tuple(roles[order]),
        approach=approach,
        directions=dirs[1::2],
        criterion=criterion,
        indices=observability_indices(blocks[design.indices]),
        table1_indices=observability_indices(table1),
        value=design.value,
        n_candidates=cand.shape[0],
        travel_mm=tour_length(waypoints, home),
    )
