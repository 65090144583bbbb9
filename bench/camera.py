"""Camera calibration benchmark: how well one camera and two printed boards measure B, and
how good the identified profile is, against the motion-capture path as the baseline.

Run: python bench/camera.py [--quick] [--poses 15] [--frames 4] [--seeds 1]

Every session is rendered by the simulated camera (cdprhost.sim.camera) from a true machine
off the nominal ``paper-simulation`` by U(-3, 3) mm per parameter, at poses planned
D-optimally among those the camera sees (camera_visibility), with intrinsics calibrated
from 18 rendered views (what a user gets, not the truth).

1. **Detection speed**: frames per second of finding both boards (sub-pixel corners) per
   picture size (wall clock: noisy on a loaded machine).
2. **Per-pose error of B** against the truth, split into depth (along the camera's line of
   sight) and lateral, RMS over poses: per frame on its own (the baseline), the
   session-level fit with the camera alone, and refined with the robot's motion; then the
   **workspace RMS** of the identified profile against the truth (validation grid) and the
   trust gate's prediction of it (ratio predicted / true). Rows: the reference set-up
   (1920x1080, 70 deg, 0.7 m, ordinary blur, noise, JPEG 92), other resolutions, distances,
   blur, noise, a phone at 0.5 m, and intrinsics calibrated by the reader from views.
3. **Pose count**: workspace RMS at the reference set-up for 6 to 20 fit poses.
4. **Motion capture baseline**: the same truths and poses measured by the virtual motion
   capture (realistic takes), identified the same way.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.calibration.camera.detection import detect_board
from cdprhost.calibration.camera.positions import effector_positions
from cdprhost.calibration.camera.session_fit import fit_session
from cdprhost.calibration.camera.takes import read_camera_session
from cdprhost.calibration.planning import candidate_poses, plan_poses
from cdprhost.calibration.session import load_session
from cdprhost.calibration.session_identification import identify_session
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile
from cdprhost.sim.camera.imaging import Imaging, decode
from cdprhost.sim.camera.scene import CameraRig, phone_rig, standard_rig
from cdprhost.sim.camera.session import calibrated_intrinsics, write_camera_session
from cdprhost.sim.measurement import achieved_points, perturbed_geometry
from cdprhost.sim.scenarios import session_times
from cdprhost.sim.synthetic_session import write_measured_session
from cdprhost.sim.virtual_mocap import REALISTIC


def validation_rms(truth: MachineModel, commanding: MachineModel, grid: np.ndarray) -> float:
    err = np.linalg.norm(achieved_points(truth, commanding, grid) - grid, axis=1)
    return float(np.sqrt(np.nanmean(err**2))) if np.isfinite(err).any() else float("inf")


def split_error(
    err: np.ndarray, points: np.ndarray, camera_position: np.ndarray
) -> tuple[float, float]:
    """RMS of the error's depth (along the line of sight) and lateral parts."""
    ok = np.isfinite(err).all(axis=1)
    if not ok.any():
        return float("nan"), float("nan")
    sight = points[ok] - camera_position
    sight /= np.linalg.norm(sight, axis=1, keepdims=True)
    depth = np.sum(err[ok] * sight, axis=1)
    lateral = np.linalg.norm(err[ok] - depth[:, None] * sight, axis=1)
    return float(np.sqrt(np.mean(depth**2))), float(np.sqrt(np.mean(lateral**2)))


def rigs(quick: bool) -> dict[str, CameraRig]:
    ref = standard_rig()
    out = {"1080p 0.7 m (reference)": ref}
    if quick:
        return out
    out.update(
        {
            "720p 0.7 m": standard_rig(image_size=(1280, 720)),
            "1080p 0.5 m": standard_rig(distance_mm=500.0),
            "1080p 1.0 m": standard_rig(distance_mm=1000.0),
            "1080p blur 2 px": standard_rig(imaging=Imaging(psf_px=1.2, motion_px=2.0)),
            "1080p noisy, dim, JPEG 75": standard_rig(
                imaging=Imaging(full_well_e=2000.0, read_noise_e=12.0, light=0.35, jpeg_quality=75)
            ),
            "phone 1920x1440 0.5 m": phone_rig(),
        }
    )
    return out


def plan_for(rig: CameraRig, nominal: MachineModel, n: int, seed: int) -> np.ndarray:
    cand = candidate_poses(nominal)
    return plan_poses(nominal, n, candidates=cand[rig.visible(cand)], seed=seed).poses


def camera_row(
    rig: CameraRig,
    truth: MachineModel,
    nominal: MachineModel,
    poses: np.ndarray,
    folder: Path,
    frames: int,
    intrinsics: Any = "calibrated",
    seed: int = 0,
) -> dict[str, Any]:
    s = write_camera_session(
        folder,
        truth,
        nominal,
        poses,
        rig=rig,
        frames_per_take=frames,
        intrinsics=intrinsics,  # type: ignore[arg-type]
        seed=seed,
        t_s=session_times(len(poses), np.random.default_rng(seed)),
    )
    session = load_session(folder)
    assert session.config.camera is not None
    data = read_camera_session(folder, session.config.camera, session.take_paths)
    cam = rig.camera.position
    row: dict[str, Any] = {}
    per_frame = []
    for t in data.takes:
        assert t is not None
        fp = effector_positions(
            list(t.detections.reference), list(t.detections.effector), data.setup, data.intrinsics
        )
        per_frame.append(np.nanmean(fp.positions, axis=0) if fp.valid.any() else np.full(3, np.nan))
    row["frame"] = split_error(np.array(per_frame) - s.actual, s.actual, cam)
    alone = fit_session(data.detections(), data.setup, data.intrinsics)
    row["session"] = split_error(alone.positions - s.actual, s.actual, cam)
    refined = fit_session(data.detections(), data.setup, data.intrinsics, s.s_cmd, nominal)
    row["refined"] = split_error(refined.positions - s.actual, s.actual, cam)
    result = identify_session(folder, nominal)
    grid = workspace_grid(nominal)
    row["rms"] = validation_rms(truth, result.model, grid) if result.solved else float("inf")
    row["predicted"] = result.predicted_workspace_rms_mm
    row["ok"] = result.ok
    return row


def fmt(pair: tuple[float, float]) -> str:
    return f"{pair[0]:6.3f} / {pair[1]:6.3f}"


def detection_speed(quick: bool) -> None:
    print("\n1. detection speed (both boards per picture; wall clock, noisy under load)")
    sizes = [(1920, 1080)] if quick else [(1280, 720), (1920, 1080)]
    for size in sizes:
        rig = standard_rig(image_size=size)
        r = rig.renderer()
        rig.frame(r, np.array([0.0, 0.0, 220.0]), np.random.default_rng(0))  # rays cached
        t0 = time.perf_counter()
        pics = [
            decode(rig.frame(r, np.array([0.0, 0.0, 220.0]), np.random.default_rng(i)))
            for i in range(4)
        ]
        render_fps = 4 / (time.perf_counter() - t0)
        t0 = time.perf_counter()
        n = 0
        for img in pics * 2:
            detect_board(img, rig.setup.reference.board)
            detect_board(img, rig.setup.effector.board)
            n += 1
        dt = time.perf_counter() - t0
        print(
            f"  {size[0]}x{size[1]}: detection {n / dt:6.1f} frames/s "
            f"(the simulated camera renders {render_fps:.1f} frames/s)"
        )


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="the reference set-up only")
    ap.add_argument("--poses", type=int, default=15)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument(
        "--rows",
        default="",
        metavar="WORDS",
        help="comma-separated words: only the set-ups whose name contains one (e.g. phone,720p); "
        "sections 1, 3 and 4 are skipped",
    )
    args = ap.parse_args()
    nominal = MachineModel.from_profile(load_profile("paper-simulation"))
    if not args.rows:
        detection_speed(args.quick)
    truths = [
        nominal.with_geometry(perturbed_geometry(nominal.geometry, np.random.default_rng(100 + s)))
        for s in range(args.seeds)
    ]
    print(
        f"\n2. per-pose error of B (RMS depth / lateral, mm) and workspace RMS (mm); {args.poses} "
        f"fit poses, {args.frames} frames per take, {args.seeds} seed(s)"
    )
    print(
        f"  {'set-up':28s} {'per frame':>15s} {'session fit':>15s} {'refined':>15s} {'workspace':>9s} {'pred/true':>9s} ok"
    )
    with tempfile.TemporaryDirectory() as tmp:
        cases = [(name, rig, "calibrated") for name, rig in rigs(args.quick).items()]
        cases.append(("1080p intrinsics from views", standard_rig(), "views"))
        words = [w.strip() for w in args.rows.split(",") if w.strip()]
        if words:
            cases = [c for c in cases if any(w in c[0] for w in words)]
        for name, rig, source in cases:
            if source == "calibrated":  # one calibration per camera, as a user makes
                calib = calibrated_intrinsics(rig)
                source = calib.intrinsics
                f_err = calib.intrinsics.vector[0] / rig.camera.matrix[0, 0] - 1
                print(f"  ({name}: calibrated focal length off by {100 * f_err:+.3f} %)")
            for seed, truth in enumerate(truths):
                poses = plan_for(rig, nominal, args.poses, seed)
                row = camera_row(
                    rig,
                    truth,
                    nominal,
                    poses,
                    Path(tmp) / f"{name.replace(' ', '_')}-{seed}",
                    args.frames,
                    source,
                    seed,
                )
                print(
                    f"  {name:28s} {fmt(row['frame'])} {fmt(row['session'])} {fmt(row['refined'])} "
                    f"{row['rms']:9.3f} {row['predicted'] / row['rms']:9.2f} {row['ok']}"
                )
        if words:
            return 0
        print("\n3. workspace RMS vs fit poses (reference set-up)")
        rig = standard_rig()
        calib = calibrated_intrinsics(rig).intrinsics
        for n in (6, 10, 15, 20) if not args.quick else (15,):
            poses = plan_for(rig, nominal, n, 0)
            row = camera_row(
                rig, truths[0], nominal, poses, Path(tmp) / f"n{n}", args.frames, calib
            )
            print(
                f"  {n:3d} poses: workspace RMS {row['rms']:.3f} mm (predicted {row['predicted']:.3f})"
            )
        print(
            "\n4. motion capture baseline (virtual mocap, realistic takes; same truths and poses)"
        )
        for seed, truth in enumerate(truths):
            poses = plan_for(rig, nominal, args.poses, seed)
            folder = Path(tmp) / f"mocap{seed}"
            rng = np.random.default_rng(seed)
            write_measured_session(
                folder,
                truth,
                nominal,
                poses,
                session_times(len(poses), rng),
                realism=REALISTIC,
                seed=seed,
            )
            result = identify_session(folder, nominal)
            rms = validation_rms(truth, result.model, workspace_grid(nominal))
            print(
                f"  seed {seed}: workspace RMS {rms:.3f} mm (predicted {result.predicted_workspace_rms_mm:.3f}), ok {result.ok}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
