"""Kinematics throughput: vectorised IK (+ steps) and closed-form FK vs a per-point Python loop.

Run: python bench/kinematics.py [--points N]
Prints points/s for each and the ratio against the per-point loop measured in the
same run (the baseline). Targets on a 2-core machine: IK >= 4e6 points/s,
FK >= 5e6 points/s (ideal model).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile


def best_rate(fn, n: int, repeats: int = 5) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def loop_ik(points, outlets, l0, spm):
    out = []
    for x, y, z in points:
        row = []
        for k in range(3):
            ax, ay, az = outlets[k]
            s = math.sqrt((x - ax) ** 2 + (y - ay) ** 2 + (z - az) ** 2) - l0[k]
            row.append(round(s * spm[k]))
        out.append(row)
    return out


def loop_fk(sliders, outlets, l0):
    """Three-sphere intersection one point at a time with the math module."""
    (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = outlets
    ex = [x2 - x1, y2 - y1, z2 - z1]
    d = math.sqrt(sum(c * c for c in ex))
    ex = [c / d for c in ex]
    a3 = [x3 - x1, y3 - y1, z3 - z1]
    i = sum(a * b for a, b in zip(ex, a3))
    ey = [a - i * e for a, e in zip(a3, ex)]
    j = math.sqrt(sum(c * c for c in ey))
    ey = [c / j for c in ey]
    ez = [
        ex[1] * ey[2] - ex[2] * ey[1],
        ex[2] * ey[0] - ex[0] * ey[2],
        ex[0] * ey[1] - ex[1] * ey[0],
    ]
    if ez[2] < 0:
        ez = [-c for c in ez]
        ey = [-c for c in ey]
        j = -j
    out = []
    for s1, s2, s3 in sliders:
        r1, r2, r3 = s1 + l0[0], s2 + l0[1], s3 + l0[2]
        x = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
        y = (r1 * r1 - r3 * r3 + i * i + j * j) / (2 * j) - i / j * x
        z = math.sqrt(r1 * r1 - x * x - y * y)
        out.append(
            [
                x1 + x * ex[0] + y * ey[0] + z * ez[0],
                y1 + x * ex[1] + y * ey[1] + z * ez[1],
                z1 + x * ex[2] + y * ey[2] + z * ez[2],
            ]
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--profile", default="paper-simulation")
    args = ap.parse_args()
    model = MachineModel.from_profile(load_profile(args.profile))
    rng = np.random.default_rng(0)
    n = args.points
    pts = rng.uniform([-40, -40, 120], [40, 40, 320], (n, 3))
    sliders = model.ik(pts)
    ik_rate = best_rate(lambda: model.steps(model.ik(pts)), n)
    fk_rate = best_rate(lambda: model.fk(sliders), n)
    m = 20_000
    outlets = model.geometry.outlets.tolist()
    l0 = model.geometry.initial_lengths.tolist()
    spm = model.steps_per_mm.tolist()
    small = pts[:m].tolist()
    loop_ik_rate = best_rate(lambda: loop_ik(small, outlets, l0, spm), m, repeats=3)
    small_s = sliders[:m].tolist()
    loop_fk_rate = best_rate(lambda: loop_fk(small_s, outlets, l0), m, repeats=3)
    print(f"{'operation':<24}{'points/s':>14}{'vs per-point loop':>20}{'target':>12}")
    print(
        f"{'IK + steps (numpy)':<24}{ik_rate:>14.3e}{ik_rate / loop_ik_rate:>19.0f}x{'>= 4e6':>12}"
    )
    print(
        f"{'FK closed form (numpy)':<24}{fk_rate:>14.3e}{fk_rate / loop_fk_rate:>19.0f}x{'>= 5e6':>12}"
    )
    print(f"{'baseline IK loop':<24}{loop_ik_rate:>14.3e}")
    print(f"{'baseline FK loop':<24}{loop_fk_rate:>14.3e}")


if __name__ == "__main__":
    main()
