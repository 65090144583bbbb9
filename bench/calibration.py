"""Calibration accuracy: workspace-wide error after calibrating from simulated sessions.

Run: python bench/calibration.py [--seeds 50] [--noise 0.05]

For each seed a true machine differs from the nominal ``paper-simulation`` profile
by U(-3, 3) mm in each of the 12 parameters. A session is simulated (poses
commanded through the nominal model, the true effector measured with Gaussian
mocap noise per coordinate), the 12 parameters are identified, and the calibrated
model then drives the true machine over a validation grid at five heights: the
RMS of commanded-minus-achieved over the grid is the score. Pose sets: the
paper's Table 1 (the baseline of this run), 4 planned poses and 12 planned
poses. Targets: planned 12 <= 0.12 mm, planned 4 <= 0.3 mm (median over seeds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cdprhost.calibration.identification import identify
from cdprhost.calibration.planning import TABLE1_POSES, plan_poses
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile
from cdprhost.sim.measurement import achieved_points, perturbed_geometry, simulate_observations

TARGETS_MM = {"planned 4": 0.3, "planned 12": 0.12}


def validation_rms(truth: MachineModel, commanding: MachineModel, grid: np.ndarray) -> float:
    """RMS distance between grid targets and where ``commanding`` really puts the effector."""
    err = np.linalg.norm(achieved_points(truth, commanding, grid) - grid, axis=1)
    return float(np.sqrt(np.nanmean(err**2))) if np.isfinite(err).any() else float("inf")


def session_scores(
    nominal: MachineModel,
    pose_sets: dict[str, np.ndarray],
    seeds: range,
    noise_mm: float = 0.05,
    amplitude_mm: float = 3.0,
) -> dict[str, np.ndarray]:
    """Validation RMS after calibration, per pose set and seed; key ``before`` = nominal."""
    grid = workspace_grid(nominal)
    scores: dict[str, list[float]] = {"before": [], **{k: [] for k in pose_sets}}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        truth = nominal.with_geometry(perturbed_geometry(nominal.geometry, rng, amplitude_mm))
        scores["before"].append(validation_rms(truth, nominal, grid))
        for name, poses in pose_sets.items():
            obs = simulate_observations(truth, nominal, poses, noise_mm=noise_mm, rng=rng)
            if not np.isfinite(
                obs.measured
            ).all():  # the true effector cannot reach a commanded pose
                scores[name].append(float("inf"))
                continue
            result = identify(obs, nominal)
            scores[name].append(
                validation_rms(truth, result.model, grid) if result.converged else float("inf")
            )
    return {k: np.asarray(v) for k, v in scores.items()}


def standard_pose_sets(nominal: MachineModel) -> dict[str, np.ndarray]:
    return {
        "Table 1": TABLE1_POSES,
        "planned 4": plan_poses(nominal, 4).poses,
        "planned 12": plan_poses(nominal, 12).poses,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--noise", type=float, default=0.05, help="mocap noise per coordinate (mm)")
    ap.add_argument("--profile", default="paper-simulation")
    args = ap.parse_args()
    nominal = MachineModel.from_profile(load_profile(args.profile))
    t0 = time.perf_counter()
    sets = standard_pose_sets(nominal)
    t_plan = time.perf_counter() - t0
    scores = session_scores(nominal, sets, range(args.seeds), args.noise)
    np.seterr(invalid="ignore")  # medians and ratios over failed (inf) sessions
    t_run = time.perf_counter() - t0 - t_plan
    base = float(np.median(scores["Table 1"]))
    print(
        f"{args.seeds} seeds, mocap noise {args.noise} mm/coordinate, true errors U(-3, 3) mm; "
        f"planning {t_plan:.1f} s, sessions {t_run:.1f} s"
    )
    print(
        "validation RMS (mm) over",
        len(workspace_grid(nominal)),
        "grid points; 'failed' = a pose the true machine cannot reach or no convergence",
    )
    print(
        f"{'pose set':<12} {'median':>10} {'p90':>10} {'failed':>7} {'vs Table 1':>11} {'target':>9}"
    )
    for name, vals in scores.items():
        med = float(np.median(vals))
        target = TARGETS_MM.get(name)
        mark = "" if target is None else (f"{target:g} ok" if med <= target else f"{target:g} MISS")
        print(
            f"{name:<12} {med:10.4f} {np.sort(vals)[int(0.9 * (vals.size - 1))]:10.4f} {int(np.sum(~np.isfinite(vals))):7d} "
            f"{base / med:10.1f}x {mark:>9}"
        )
    return 0 if all(float(np.median(scores[k])) <= v for k, v in TARGETS_MM.items()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
