"""A camera session measured: pictures -> the session-level fit -> each pose's B with its
covariance, judged take by take like motion-capture takes (camera-session.md).

The boards are found in every frame (:func:`~.camera.takes.read_camera_session`), the
session-level fit (:func:`~.camera.session_fit.fit_session`) solves one camera and one
board orientation with the intrinsics refined against the robot's commanded motion (on
the fit poses only, so that check poses still test it), and every take's frames are then
judged by the statistical take test (settling, drift, spread, missing frames). A take whose
boards are not seen well enough in enough frames is refused naming the board and the
frames; calibration views of poor coverage refuse the session (their reason and the views
to add). A take's drift is tested against the camera's own frame noise (anisotropic:
depth is worst; :mod:`~.camera.take_drift`), not against the few frames' scatter, and
so is their scatter (:mod:`~.camera.take_scatter`), not against the motion-capture cap.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.camera.config import CameraConfig
from cdprhost.calibration.camera.session_fit import SessionFit, TakeDetections, fit_session
from cdprhost.calibration.camera.take_drift import CameraDrift, camera_drift
from cdprhost.calibration.camera.take_scatter import camera_scatter
from cdprhost.calibration.camera.takes import read_camera_session, skipped_text
from cdprhost.calibration.measurements import RejectedTake, SessionMeasurements
from cdprhost.calibration.poses import PoseTable
from cdprhost.calibration.takes import TakeMeasurement, TakeRejected, TakeSeries, judge_takes
from cdprhost.errors import InputError
from cdprhost.kinematics.machine import MachineModel

#: A camera take has a few frames, not hundreds: the fewest it may have (unless
#: ``[camera.acceptance] min_frames`` says otherwise).
CAMERA_MIN_FRAMES = 3
#: The mocap drift limit handed to the generic take test (whose drift test a camera take
#: has already passed on the camera's noise): a drift no take reaches.
NO_DRIFT_LIMIT = 1e9
#: Likewise the mocap spread cap (a camera take's scatter is tested on the camera's noise),
#: unless ``[camera.acceptance] max_spread_mm`` sets one.
NO_SPREAD_LIMIT = 1e9

#: Smallest drift over a camera take that matters (mm): a frame's B scatters by tenths of a
#: millimetre, and a drift test on a few frames must not refuse takes for that.
CAMERA_MAX_DRIFT_MM = 0.5
#: Smallest scatter of a camera take's frames about their line that matters (mm RMS): the
#: frame-noise model leaves out micrometre effects (the effector's own jitter), so a take
#: whose frames lie within tens of micrometres is never refused, however improbable.
CAMERA_MIN_SPREAD_MM = 0.05


def camera_limits(limits: AcceptanceLimits) -> AcceptanceLimits:
    """The take thresholds for pictures (unless the session sets them): a few frames
    suffice, and a drift matters only when it is as large as a frame's scatter."""
    defaults = {"min_frames": CAMERA_MIN_FRAMES, "max_drift_mm": CAMERA_MAX_DRIFT_MM}
    update = {k: v for k, v in defaults.items() if k not in limits.model_fields_set}
    return limits.model_copy(update=update)


def measure_camera_session(
    directory: Path,
    camera: CameraConfig,
    poses: PoseTable,
    take_paths: Sequence[Path],
    model: MachineModel | None,
    limits: AcceptanceLimits | None = None,
    *,
    declared_noise_mm: float | None = None,
    refine: bool = True,
) -> SessionMeasurements:
    """Every take of a camera session measured (refused ones listed, not used): the session
    folder ``directory`` with its ``[camera]`` table, its poses.csv and the take folders of
    its rows; with ``model`` (the profile that commanded the poses) and ``refine``, the
    intrinsics are refined against the robot's motion. Raises InputError when no frame
    shows the reference board well enough (naming the frames)."""
    lim = camera_limits(limits or camera.acceptance)
    data = read_camera_session(directory, camera, tuple(take_paths))
    p = poses
    fit_rows = np.array([r != "check" for r in (p.roles or ("fit",) * len(p))])
    try:
        fit = fit_session(
            data.detections(),
            data.setup,
            data.intrinsics,
            p.s_cmd if refine and model is not None else None,
            model if refine else None,
            fit_rows=fit_rows,
        )
    except ValueError as exc:
        named = "; ".join(
            f"pose {p.pose[i]}: {skipped_text(t.names, tuple(_frame_reasons(t)))}"
            for i, t in enumerate(data.takes[:6])
            if t is not None
        )
        raise InputError(
            f"{exc}" + (f" ({named})" if named else ""), source=str(directory)
        ) from None
    rejected: list[RejectedTake] = [
        RejectedTake(int(p.pose[i]), p.take[i], "unreadable", msg)
        for i, msg in data.unreadable.items()
    ]
    series: list[TakeSeries] = []
    rows: list[int] = []
    drifts: dict[int, CameraDrift] = {}
    for i, take in enumerate(data.takes):
        if take is None:
            continue
        skipped = fit.frame_skipped[i]
        usable = sum(1 for s in skipped if not s)
        if not np.isfinite(fit.positions[i]).all() or usable < lim.min_valid_fraction * len(
            skipped
        ):
            rejected.append(
                RejectedTake(
                    int(p.pose[i]),
                    p.take[i],
                    "missing-marker",
                    f"{usable} of {len(skipped)} frames usable: {skipped_text(take.names, skipped)}",
                )
            )
            continue
        scatter = camera_scatter(
            fit.frame_positions[i], take.detections.times, _frame_noise(fit, i)
        )
        if scatter.p < lim.drift_alpha and scatter.rms_mm > CAMERA_MIN_SPREAD_MM:
            rejected.append(
                RejectedTake(
                    int(p.pose[i]),
                    p.take[i],
                    "spread",
                    f"frames scatter {scatter.rms_mm:.3f} mm RMS about their line where the "
                    f"camera's frame noise predicts {scatter.expected_rms_mm:.3f} mm "
                    f"({scatter.ratio:.1f}x; p = {scatter.p:.1e}; limits: p < {lim.drift_alpha:g} and "
                    f"> {CAMERA_MIN_SPREAD_MM:g} mm): "
                    "the effector is shaking or the board moved between frames",
                )
            )
            continue
        drift = camera_drift(fit.frame_positions[i], take.detections.times, _frame_noise(fit, i))
        if drift.p < lim.drift_alpha and drift.total_mm > lim.max_drift_mm:
            d = drift.drift_mm
            rejected.append(
                RejectedTake(
                    int(p.pose[i]),
                    p.take[i],
                    "drift",
                    f"effector crept {drift.total_mm:.3f} mm over {drift.duration_s:.2f} s "
                    f"(dx {d[0]:+.3f}, dy {d[1]:+.3f}, dz {d[2]:+.3f} mm; p = {drift.p:.1e} "
                    f"against the camera's frame noise; limits: p < {lim.drift_alpha:g} and "
                    f"> {lim.max_drift_mm:g} mm)",
                )
            )
            continue
        drifts[i] = drift
        series.append(
            TakeSeries(
                fit.frame_positions[i],
                take.detections.times,
                np.zeros(3),
                0.0,
                (),
                str(take_paths[i] if take_paths else directory / p.take[i]),
            )
        )
        rows.append(i)
    # drift and scatter were judged above on the camera's noise: the frames' own scatter
    # (a few frames) and the motion-capture caps are not asked again
    judged = judge_takes(series, _generic_limits(lim))
    keep: list[int] = []
    results: list[TakeMeasurement] = []
    for i, r in zip(rows, judged):
        if isinstance(r, TakeRejected):
            rejected.append(RejectedTake(int(p.pose[i]), p.take[i], r.reason, str(r)))
        else:
            keep.append(i)
            results.append(r)
    rejected.sort(key=lambda r: r.pose)
    k = np.asarray(keep, dtype=int)
    cov = _pose_covariances(fit, k, [drifts[i] for i in keep], lim)
    refusals: tuple[str, ...] = ()
    calibration = data.calibration
    seen = _boards_seen_px(data.detections())
    if calibration is not None and len(seen):
        # the lens must be known where this session's boards are seen, not everywhere
        calibration = calibration.judged_for(seen, "where this session's boards are seen")
    if calibration is not None and not calibration.ok:
        refusals = tuple(
            f"the calibration views ({camera.calibration_views}): {text}"
            for text in calibration.problems
        )
    return SessionMeasurements(
        p.pose[k],
        tuple(p.roles[i] for i in keep) if p.roles else ("fit",) * len(keep),
        fit.positions[k].reshape(-1, 3),
        p.commanded[k],
        p.s_cmd[k],
        p.t_s[k],
        p.dirs[k],
        np.sqrt(np.diagonal(cov, axis1=1, axis2=2)).reshape(-1, 3),
        np.zeros(len(keep)),
        tuple(results),
        tuple(rejected),
        declared_noise_mm,
        covariance=cov,
        common_covariance=fit.common_covariance,
        parameter_covariance=fit.geometry_covariance_extra,
        frame_covariance=fit.frame_covariance,
        refusals=refusals,
        notes=_fit_notes(fit),
    )


def _generic_limits(lim: AcceptanceLimits) -> AcceptanceLimits:
    """The limits handed to the source-neutral take test once drift and scatter have been
    judged on the camera's noise: no drift limit, and the spread cap only if the session
    sets one."""
    update: dict[str, float] = {"max_drift_mm": NO_DRIFT_LIMIT, "motion_alpha": 0.0}
    if "max_spread_mm" not in lim.model_fields_set:
        update["max_spread_mm"] = NO_SPREAD_LIMIT
    return lim.model_copy(update=update)


def _frame_reasons(take: object) -> list[str]:
    """Why each frame of a take shows no usable board (before any fit)."""
    dets = getattr(take, "detections", None)
    if dets is None:
        return []
    out = []
    for r, e in zip(dets.reference, dets.effector):
        out.append(
            "reference board not found"
            if r is None
            else "effector board not found"
            if e is None
            else ""
        )
    return out


def _boards_seen_px(takes: list[TakeDetections]) -> np.ndarray:
    """(N, 2) px: every corner of either board in the first frame of every take."""
    pts = [
        d.corners_px
        for t in takes
        for d in (t.reference[:1] + t.effector[:1])
        if d is not None and len(d)
    ]
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def _frame_noise(fit: SessionFit, row: int) -> np.ndarray:
    """One frame's covariance at pose ``row`` (NaN when the fit has none)."""
    cov = fit.frame_noise_covariances
    return cov[row] if row < len(cov) else np.full((3, 3), np.nan)


def _pose_covariances(
    fit: SessionFit, rows: np.ndarray, drifts: list[CameraDrift], lim: AcceptanceLimits
) -> np.ndarray:
    """Each kept pose's covariance: its corners' noise through the pose solution (the frames'
    own scatter is not used: a few frames give a poor standard error, and the corners'
    noise already counts them), plus the motion of a take whose drift is significant
    against the camera's noise (drift / sqrt(12) per coordinate)."""
    cov = np.array(fit.covariances[rows]).reshape(-1, 3, 3)
    for j, d in enumerate(drifts):
        if d.p < lim.motion_alpha:
            cov[j] = cov[j] + np.diag(np.asarray(d.drift_mm) ** 2 / 12.0)
    return cov


def _fit_notes(fit: SessionFit) -> tuple[str, ...]:
    notes = list(fit.notes)
    if fit.refined:
        notes.append(
            "camera refined against the robot's motion: "
            + ", ".join(fit.refined)
            + f" (corner noise {fit.pixel_sigma:.3f} px)"
        )
    common = float(np.sqrt(np.trace(fit.common_covariance)))
    if common > 0:
        notes.append(
            f"every B shares one unknown vector of {common:.3g} mm RMS (effector-board "
            "orientation x offset, offset as printed): identification cannot see it; the "
            "trust gate counts it"
        )
    return tuple(notes)
