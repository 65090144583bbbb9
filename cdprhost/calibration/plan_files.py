"""Plan files: a :class:`~cdprhost.calibration.planning.PosePlan` as CSV (``calibrate plan
--out`` and a wizard session's plan.csv) and back."""

from __future__ import annotations

import csv
import io
import os

import numpy as np

from cdprhost.calibration.planning import (
    TABLE1_POSES,
    PosePlan,
    observability_indices,
    pose_blocks,
    tour_length,
)
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel

PLAN_COLUMNS = (
    "pose",
    "role",
    "x",
    "y",
    "z",
    "approach_x",
    "approach_y",
    "approach_z",
    "dir1",
    "dir2",
    "dir3",
)


def plan_csv(plan: PosePlan) -> str:
    """The plan as CSV text (``calibrate plan --out`` and a wizard session's plan.csv)."""
    added = any(plan.round_of(i) for i in range(len(plan.poses)))
    lines = [",".join(PLAN_COLUMNS + (("round",) if added else ()))]
    for i, (p, role, a, d) in enumerate(
        zip(plan.poses, plan.roles, plan.approach, plan.directions)
    ):
        cells = [str(i + 1), role, *(f"{v:.6f}" for v in (*p, *a)), *(str(int(v)) for v in d)]
        lines.append(",".join(cells + ([str(plan.round_of(i))] if added else [])))
    return "\n".join(lines) + "\n"


def read_plan_csv(path: str | os.PathLike[str], model: MachineModel | None = None) -> PosePlan:
    """A plan file back as a :class:`PosePlan` (indices recomputed when ``model`` is given)."""
    src = str(path)
    try:
        with open(path, encoding="utf-8-sig") as fh:
            rows = list(csv.reader(io.StringIO(fh.read())))
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=src) from None
    header = [h.strip() for h in rows[0]] if rows else []
    missing = [c for c in PLAN_COLUMNS if c not in header]
    if missing:
        raise InputError(f"line 1: header lacks column(s) {', '.join(missing)}", source=src)
    col = {c: header.index(c) for c in PLAN_COLUMNS}
    roles, values, rounds = [], [], []
    round_col = header.index("round") if "round" in header else None
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        role = row[col["role"]].strip()
        if role not in ("fit", "check"):
            raise InputError(
                f"line {n}, column 'role': must be fit or check, got {role!r}", source=src
            )
        try:
            values.append([float(row[col[c]]) for c in PLAN_COLUMNS[2:]])
        except (ValueError, IndexError):
            raise InputError(
                f"line {n}: expected numbers in columns {', '.join(PLAN_COLUMNS[2:])}", source=src
            ) from None
        roles.append(role)
        try:
            rounds.append(int(row[round_col]) if round_col is not None else 0)
        except (ValueError, IndexError):
            raise InputError(f"line {n}, column 'round': not an integer", source=src) from None
    v = np.asarray(values, dtype=float).reshape(-1, 9)
    if not np.isfinite(v).all():
        raise InputError("non-finite number in a pose row", source=src)
    fit = v[np.array(roles) == "fit", :3] if roles else np.zeros((0, 3))
    indices = (
        observability_indices(pose_blocks(model, fit))
        if model is not None and len(fit) >= 4
        else {}
    )
    table1 = observability_indices(pose_blocks(model, TABLE1_POSES)) if model is not None else {}
    start = (
        model.home_point(np.zeros(3)) if model is not None else v[0, 3:6] if len(v) else np.zeros(3)
    )
    way = np.empty((2 * len(v), 3))
    way[0::2], way[1::2] = v[:, 3:6], v[:, :3]
    return PosePlan(
        v[:, :3],
        tuple(roles),
        v[:, 3:6],
        v[:, 6:9],
        "file",
        indices,
        table1,
        float("nan"),
        0,
        tour_length(way, start),
        tuple(rounds),
    )
