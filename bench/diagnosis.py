"""Diagnosis wall time: a 40-pose session, the whole effect catalogue, cross-validation.

Run: python bench/diagnosis.py [--runs N] [--poses K] [--effect NAME]
Prints the median wall time of the full workflow (default settings: 8-fold held-out
error for every candidate), of the fast settings used by the statistical tests, and
of reading a 40-take Motive CSV session folder, each against the baseline measured
in the same run: one base-model fit (the 12 geometric parameters). Target: full
diagnosis under 10 s on a 2-core machine.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.fitting import CableModelFit
from cdprhost.diagnosis.session_input import load_session_data
from cdprhost.diagnosis.workflow import FAST, DiagnosisSettings, diagnose
from cdprhost.effects.base import MotionContext
from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times, simulate_session
from cdprhost.sim.synthetic_session import write_synthetic_session


def median_time(fn, runs: int) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def write_session(directory: Path, nominal: MachineModel, effect: str, n_poses: int) -> None:
    rng = np.random.default_rng(1)
    truth = hidden_truth(nominal, rng, effect)
    poses = measurement_tour(nominal, n_poses, rng)
    t_s = session_times(n_poses, rng)
    s_cmd, dirs = commanded_path(nominal, poses)
    actual = truth.fk(s_cmd, MotionContext(t_s=t_s, directions=dirs))
    write_synthetic_session(
        directory, actual, poses, s_cmd, t_s, dirs.astype(int), "paper-simulation"
    )


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--poses", type=int, default=40)
    ap.add_argument(
        "--effect", default="cable_elasticity", help="hidden effect (default: the slowest to fit)"
    )
    args = ap.parse_args()
    nominal = MachineModel.from_profile(load_profile("paper-simulation"))
    rng = np.random.default_rng(0)
    truth = hidden_truth(nominal, rng, args.effect)
    _, obs = simulate_session(truth, nominal, rng, n_poses=args.poses)

    base = median_time(lambda: CableModelFit().fit(obs, nominal), max(args.runs, 5))
    verdicts = []
    full = median_time(
        lambda: verdicts.append(diagnose(obs, nominal, settings=DiagnosisSettings())), args.runs
    )
    fast = median_time(lambda: diagnose(obs, nominal, settings=FAST), args.runs)
    with tempfile.TemporaryDirectory() as tmp:
        write_session(Path(tmp), nominal, args.effect, args.poses)
        read = median_time(lambda: load_session_data(tmp), max(1, args.runs // 2))

    d = verdicts[-1]
    print(
        f"{args.poses} poses, hidden {args.effect}: verdict {d.verdict} {', '.join(d.effects)}; "
        f"held-out {d.base.heldout_rms_mm:.3f} -> {d.final.heldout_rms_mm:.3f} mm, noise floor {d.noise_floor_mm:.3f} mm"
    )
    print(f"{'step':<42}{'median s':>10}{'vs base fit':>13}{'target':>10}")
    print(f"{'baseline: base-model fit (12 parameters)':<42}{base:>10.4f}{1.0:>12.0f}x")
    print(
        f"{'diagnosis, full (8 folds, all candidates)':<42}{full:>10.3f}{full / base:>12.0f}x{'< 10 s':>10}"
    )
    print(
        f"{'diagnosis, fast (4 folds, tests)':<42}{fast:>10.3f}{fast / base:>12.0f}x{'< 0.5 s':>10}"
    )
    print(f"{'read + average 40 Motive takes':<42}{read:>10.3f}{read / base:>12.0f}x")


if __name__ == "__main__":
    main()
