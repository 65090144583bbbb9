"""`cdprhost ik` and `cdprhost fk`: batch kinematics on CSV files."""

from __future__ import annotations

import argparse

import numpy as np

from cdprhost.cli.options import output_file
from cdprhost.cli.profile_arg import add_profile_argument, load_model
from cdprhost.errors import InputError
from cdprhost.fileio.csv_arrays import data_row_numbers, read_columns, write_columns


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    ik = sub.add_parser(
        "ik", help="points (x,y,z) -> slider displacements and steps, effects compensated"
    )
    add_profile_argument(ik)
    ik.add_argument(
        "--in",
        dest="inp",
        required=True,
        metavar="points.csv",
        help="header x,y,z (base frame, mm), a path in order",
    )
    ik.add_argument(
        "--out",
        type=output_file,
        required=True,
        metavar="targets.csv",
        help="header x,y,z,s1,s2,s3,n1,n2,n3",
    )
    ik.set_defaults(func=run_ik)
    fk = sub.add_parser(
        "fk", help="slider displacements (s1,s2,s3) -> effector points, effects predicted"
    )
    add_profile_argument(fk)
    fk.add_argument(
        "--in", dest="inp", required=True, metavar="targets.csv", help="header s1,s2,s3 (mm)"
    )
    fk.add_argument(
        "--out", type=output_file, required=True, metavar="points.csv", help="header s1,s2,s3,x,y,z"
    )
    fk.set_defaults(func=run_fk)


def run_ik(args: argparse.Namespace) -> int:
    _, model = load_model(args.profile)
    points = read_columns(args.inp, ("x", "y", "z"))
    sliders = model.ik(points, path=True)
    report = model.check(points, sliders)
    bad = np.flatnonzero(~report.ok)
    if bad.size:
        rows = data_row_numbers(args.inp)
        lines = [
            f"row {rows[i]}: point ({points[i, 0]:g}, {points[i, 1]:g}, {points[i, 2]:g}) fails '{report.rule_name(i)}': "
            f"{report.describe(i, model.limits)}"
            for i in bad[:20]
        ]
        if bad.size > 20:
            lines.append(f"... and {bad.size - 20} more")
        raise InputError(
            f"{bad.size} point(s) outside the workspace; nothing written",
            source=args.inp,
            problems=lines,
        )
    steps = model.steps(sliders)
    write_columns(
        args.out,
        ("x", "y", "z", "s1", "s2", "s3", "n1", "n2", "n3"),
        [*points.T, *sliders.T, *steps.T],
        ["%.10f"] * 6 + ["%d"] * 3,
    )
    return 0


def run_fk(args: argparse.Namespace) -> int:
    _, model = load_model(args.profile)
    sliders = read_columns(args.inp, ("s1", "s2", "s3"))
    _refuse_outside_travel(args.inp, sliders, np.asarray(model.limits.travel, dtype=float))
    points = model.fk(sliders)
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        rows = data_row_numbers(args.inp)
        lines = [
            f"row {rows[i]}: the three cable lengths do not meet (no effector position)"
            for i in bad[:20]
        ]
        raise InputError(
            f"{bad.size} row(s) have no forward solution; nothing written",
            source=args.inp,
            problems=lines,
        )
    write_columns(
        args.out, ("s1", "s2", "s3", "x", "y", "z"), [*sliders.T, *points.T], ["%.10f"] * 6
    )
    return 0


def _refuse_outside_travel(source: str, sliders: np.ndarray, travel: np.ndarray) -> None:
    """InputError naming every row (up to 20) whose slider lies outside its travel, as
    ``ik`` names the points outside the workspace; nothing is written."""
    lo, hi = travel[:, 0], travel[:, 1]
    outside = (sliders < lo) | (sliders > hi)
    bad = np.flatnonzero(outside.any(axis=1))
    if not bad.size:
        return
    rows = data_row_numbers(source)
    lines = []
    for i in bad[:20]:
        k = int(np.flatnonzero(outside[i])[0])
        by = lo[k] - sliders[i, k] if sliders[i, k] < lo[k] else sliders[i, k] - hi[k]
        lines.append(
            f"row {rows[i]}: s{k + 1} = {sliders[i, k]:g} mm is outside its travel "
            f"[{lo[k]:g}, {hi[k]:g}] mm by {by:.4g} mm"
        )
    if bad.size > 20:
        lines.append(f"... and {bad.size - 20} more")
    raise InputError(
        f"{bad.size} row(s) outside the sliders' travel; nothing written",
        source=source,
        problems=lines,
    )
