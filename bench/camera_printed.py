"""Issue 31's figures: workspace RMS and the trust gate's prediction on rendered camera
sessions of the kinds a user meets, intrinsics included.

Run: python bench/camera_printed.py [KIND ...] [--seeds 1] [--first 1] [--keep DIR] [--reuse]

KIND (default all): ``known`` (the true intrinsics), ``selfcal`` (self-calibrated by the
reader from 18 good views), ``printed`` (self-calibrated from 20 views of a sheet bowed
0.5 mm: one image corner never reached, views cut by the edge, two views without a
findable board), ``phone`` (1920x1440 at 0.5 m, self-calibrated), ``far720`` (1280x720 at
1.1 m, the coarse boards, self-calibrated). 1080p rigs at 0.75 m; 15 D-optimal fit poses
of 3 frames; the true machine off the nominal ``paper-simulation`` by U(-3, 3) mm per
parameter (rng 100 + seed). Prints the workspace RMS against the truth, the gate's
prediction, their ratio, the range one calibration's RMS falls in 8 times out of 10 with
the error's effective degrees of freedom, where the observed RMS falls in that predicted
distribution (quantile: uniform over many sessions when the gate is right), how often
one session's RMS lands within 1.5x of even an exact prediction, the verdict and the takes
refused (with why). ``--reuse`` identifies sessions already rendered into ``--keep`` again.
Rendering takes minutes per session.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from cdprhost.calibration.planning import candidate_poses, plan_poses
from cdprhost.calibration.session import POSES_FILE
from cdprhost.calibration.session_identification import identify_session
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile
from cdprhost.sim.camera.scene import COARSE_SETUP, CameraRig, phone_rig, standard_rig
from cdprhost.sim.camera.session import write_camera_session
from cdprhost.sim.measurement import achieved_points, perturbed_geometry

KINDS = ("known", "selfcal", "printed", "phone", "far720")


def rig_of(kind: str) -> CameraRig:
    if kind == "phone":
        return phone_rig()
    if kind == "far720":
        return standard_rig(image_size=(1280, 720), distance_mm=1100.0, setup=COARSE_SETUP)
    return standard_rig(distance_mm=750.0)


def session_options(kind: str) -> dict[str, object]:
    if kind == "known":
        return {"intrinsics": "truth"}
    if kind == "printed":
        return {
            "intrinsics": "views",
            "n_views": 20,
            "views_kind": "printed",
            "bow_mm": (0.5, 0.15),
        }
    return {"intrinsics": "views"}


def truth_and_nominal(seed: int) -> tuple[MachineModel, MachineModel]:
    """The true machine of a seed (off ``paper-simulation`` by U(-3, 3) mm per parameter)
    and the nominal one."""
    nominal = MachineModel.from_profile(load_profile("paper-simulation"))
    truth = nominal.with_geometry(
        perturbed_geometry(nominal.geometry, np.random.default_rng(100 + seed))
    )
    return truth, nominal


def render_session(kind: str, seed: int, folder: Path, reuse: bool = False) -> Path:
    """The session folder of ``kind`` and ``seed`` (rendered, or the one in ``folder`` with
    ``reuse``)."""
    if reuse and (folder / POSES_FILE).is_file():  # written last: the session is whole
        return folder
    truth, nominal = truth_and_nominal(seed)
    rig = rig_of(kind)
    cand = candidate_poses(nominal)
    poses = plan_poses(nominal, 15, candidates=cand[rig.visible(cand)], seed=seed).poses
    return write_camera_session(
        folder,
        truth,
        nominal,
        poses,
        rig=rig,
        frames_per_take=3,
        seed=seed,
        **session_options(kind),  # type: ignore[arg-type]
    ).directory


def run(kind: str, seed: int, folder: Path, reuse: bool = False) -> str:
    truth, nominal = truth_and_nominal(seed)
    t0 = time.perf_counter()
    directory = render_session(kind, seed, folder, reuse)
    result = identify_session(directory, nominal)
    grid = workspace_grid(nominal)
    err = np.linalg.norm(achieved_points(truth, result.model, grid) - grid, axis=1)
    rms = float(np.sqrt(np.mean(err**2)))
    pred = result.predicted_workspace_rms_mm
    verdict = "trusted" if result.ok else "refused"
    spread = ""
    if result.trust is not None:
        t = result.trust
        lo, hi = t.likely_rms_mm
        # how often even an exact prediction lands within 1.5x of one session's RMS
        within = t.quantile_of(1.5 * pred) - t.quantile_of(pred / 1.5)
        spread = (
            f", 80 % range {lo:.3f}-{hi:.3f} mm over {t.effective_dof:.1f} dof, "
            f"quantile {t.quantile_of(rms):.2f}, P(within 1.5x) {within:.2f}"
        )
    refused = f"{len(result.rejected)} take(s) refused" + "".join(f"; {r}" for r in result.rejected)
    return (
        f"{kind:8s} seed {seed}: workspace RMS {rms:.3f} mm, predicted {pred:.3f} mm, "
        f"ratio {pred / rms:.2f}{spread}, {verdict}, {refused} "
        f"({time.perf_counter() - t0:.0f} s)"
    )


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("kinds", nargs="*", default=list(KINDS), help=", ".join(KINDS))
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--first", type=int, default=1, help="first seed")
    ap.add_argument("--keep", metavar="DIR", help="keep the rendered sessions there")
    ap.add_argument(
        "--reuse", action="store_true", help="identify the sessions already in --keep again"
    )
    args = ap.parse_args()
    unknown = sorted(set(args.kinds) - set(KINDS))
    if unknown:
        ap.error(f"unknown kind(s) {', '.join(unknown)}; known: {', '.join(KINDS)}")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        for kind in args.kinds:
            for seed in range(args.first, args.first + args.seeds):
                print(run(kind, seed, root / f"{kind}_{seed}", args.reuse), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
