"""More poses when the trust gate refuses: D-optimal augmentation of the poses measured.

The information of the poses already measured, M0 = sum J0_i^T J0_i / sigma^2, is kept;
new poses are chosen from the feasible candidates (:func:`~.planning.candidate_poses`)
to maximise log det(M0 + sum of the new poses' information): greedily one at a time, then
improved by exchanging each new pose for the best candidate until no swap helps. Poses are
added until the predicted workspace error (:mod:`.trust`) is comfortably inside the
gate's limit and the noise becomes estimable, or a cap is reached.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.planning import (
    PosePlan,
    candidate_poses,
    column_scale,
    criterion_values,
    information,
    observability_indices,
    pose_blocks,
    tour_length,
    visiting_order,
)
from cdprhost.calibration.trust import DEFAULT_TRUST, TrustLimits, workspace_sigma
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.kinematics.jacobian import identification_jacobian
from cdprhost.kinematics.machine import MachineModel

#: New poses are added until the predicted maximum is below this fraction of the limit.
TARGET_FRACTION = 0.8


def augment_design(info: np.ndarray, base: np.ndarray, k: int, max_iter: int = 50) -> np.ndarray:
    """Indices of ``k`` candidates (information (N, 12, 12)) maximising log det(base + theirs)."""
    ridge = 1e-9 * max(float(np.trace(base)), float(np.trace(info.mean(axis=0)))) / 12.0
    total = base + ridge * np.eye(12)
    chosen: list[int] = []
    for _ in range(k):
        vals = criterion_values(total[None] + info, "D", 1)
        vals[chosen] = -np.inf
        best = int(np.argmax(vals))
        chosen.append(best)
        total = total + info[best]
    design = np.array(chosen, dtype=int)
    value = float(criterion_values(total, "D", 1))
    for _ in range(max_iter):  # exchange: the best single swap of a new pose, until none helps
        trial = total[None, None] - info[design][:, None] + info[None]  # (k, N, 12, 12)
        vals = criterion_values(trial, "D", 1)
        vals[:, design] = -np.inf
        i, j = np.unravel_index(int(np.argmax(vals)), vals.shape)
        if vals[i, j] <= value + 1e-9 * max(abs(value), 1.0):
            break
        total = total - info[design[i]] + info[j]
        design[i] = j
        value = float(vals[i, j])
    return design


def predicted_workspace(
    model: MachineModel, fit_poses: np.ndarray, sigma_mm: float | np.ndarray, grid: np.ndarray
) -> tuple[float, float]:
    """(RMS, max) predicted workspace error of identifying from ``fit_poses`` with noise
    ``sigma_mm`` per coordinate (one, or one per pose): the noise limit of a pose set (inf
    when the poses cannot determine the 12 parameters)."""
    pts = np.asarray(fit_poses, float).reshape(-1, 3)
    j0 = identification_jacobian(pts, model.geometry).reshape(-1, 3, 12)
    sig = np.broadcast_to(np.asarray(sigma_mm, dtype=float), (len(pts),))
    m = np.einsum("nip,niq,n->pq", j0, j0, 1.0 / sig**2)
    if np.linalg.matrix_rank(m, tol=1e-10 * np.trace(m)) < 12:
        return float("inf"), float("inf")
    sigma = workspace_sigma(model.geometry, np.linalg.inv(m), grid)
    return float(np.sqrt(np.mean(sigma**2))), float(np.max(sigma))


@dataclass(frozen=True)
class ExtraPoses:
    """Poses to add (in visiting order from the last measured pose) and what they promise."""

    poses: np.ndarray  # (n, 3)
    predicted_rms_mm: float
    predicted_max_mm: float
    enough: bool  # the prediction meets the target (else: the cap was reached)


def extra_poses(
    model: MachineModel,
    fit_poses: np.ndarray,
    sigma_mm: float,
    *,
    limits: TrustLimits = DEFAULT_TRUST,
    has_check_poses: bool = False,
    max_extra: int = 12,
    candidates: np.ndarray | None = None,
) -> ExtraPoses:
    """The fewest D-optimal extra fit poses that bring the predicted workspace error under
    ``TARGET_FRACTION`` of the gate's limit and give the noise degrees of freedom."""
    fit = np.asarray(fit_poses, dtype=float).reshape(-1, 3)
    cand = candidate_poses(model) if candidates is None else np.asarray(candidates, float)
    grid = workspace_grid(model)
    j0c = identification_jacobian(cand, model.geometry).reshape(-1, 3, 12)
    scale = column_scale(j0c)
    info = information(j0c / scale)
    base = (
        information(pose_blocks(model, fit, scale)).sum(axis=0) if len(fit) else np.zeros((12, 12))
    )
    target = TARGET_FRACTION * limits.max_workspace_mm
    sigma = max(float(sigma_mm), 1e-6)
    start = fit[-1] if len(fit) else model.home_point(np.zeros(3))
    best = ExtraPoses(np.zeros((0, 3)), *predicted_workspace(model, fit, sigma, grid), False)
    for n in range(1, max_extra + 1):
        idx = augment_design(info, base, n)
        new = cand[idx]
        rms, worst = predicted_workspace(model, np.vstack([fit, new]), sigma, grid)
        dof_ok = has_check_poses or 3 * (len(fit) + n) > 12
        order = visiting_order(new, start)
        best = ExtraPoses(new[order], rms, worst, worst <= target and dof_ok)
        if best.enough:
            break
    return best


def extend_plan(
    plan: PosePlan,
    model: MachineModel,
    poses: np.ndarray,
    role: str = "fit",
    approach_mm: float = 5.0,
) -> PosePlan:
    """``plan`` with ``poses`` appended (approached straight down, as planned poses are)."""
    new = np.asarray(poses, dtype=float).reshape(-1, 3)
    approach = new + np.array([0.0, 0.0, approach_mm])
    all_poses = np.vstack([plan.poses, new])
    all_approach = np.vstack([plan.approach, approach])
    way = np.empty((2 * len(all_poses), 3))
    way[0::2], way[1::2] = all_approach, all_poses
    home = model.home_point(np.zeros(3))
    _, dirs = commanded_path(model, way, start_sliders=model.ik(home[None])[0])
    roles = plan.roles + (role,) * len(new)
    done = tuple(plan.round_of(i) for i in range(len(plan.poses)))
    rounds = done + (max(done, default=0) + 1,) * len(new)
    fit = all_poses[np.array(roles) == "fit"]
    return dataclasses.replace(
        plan,
        poses=all_poses,
        roles=roles,
        approach=all_approach,
        directions=dirs[1::2],
        indices=observability_indices(pose_blocks(model, fit)) if len(fit) >= 4 else {},
        travel_mm=tour_length(way, home),
        rounds=rounds,
    )
