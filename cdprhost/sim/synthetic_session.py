"""Synthetic motion-capture takes and whole session folders (virtual mocap, tests, benchmarks).

The effector does not rotate (a cable robot of this kind translates only), so its
markers sit at fixed offsets from the effector point B, given in the base frame.
Markers are placed in the base frame, carried into the mocap world by
``mocap_pose`` (R, t: ``x_mocap = R x_base + t``; Motive's world is Y-up), and
disturbed as a real system disturbs them (:class:`~cdprhost.sim.mocap_noise.MocapNoise`:
autocorrelated jitter per marker, effector hum, settling swing, creep, runs of gaps),
or, without ``realism``, by white ``jitter_mm`` and single-cell gaps. ``noise_mm`` adds
one static offset per take on the effector markers (a positioning error that no
averaging removes and no take can show).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.mocap.readers import Take, write_take
from cdprhost.calibration.mocap.registration import rotation_about_z
from cdprhost.calibration.mocap.takes import EffectorConfig, MocapConfig
from cdprhost.calibration.session import SessionConfig
from cdprhost.calibration.session_writer import SessionWriter
from cdprhost.effects.base import MotionContext
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.mocap_noise import MocapNoise, effector_motion, gap_mask, marker_noise, vary

# The spec's example base triangle and a small effector triad 12 mm above B.
DEFAULT_BASE_MARKERS = {
    "Base:F1": (0.0, 300.0, 0.0),
    "Base:F2": (-259.8, -150.0, 0.0),
    "Base:F3": (259.8, -150.0, 0.0),
}
DEFAULT_EFFECTOR_MARKERS = {
    "EE:E1": (0.0, 25.0, 12.0),
    "EE:E2": (-21.65, -12.5, 12.0),
    "EE:E3": (21.65, -12.5, 12.0),
}
Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # base z-up -> mocap y-up


def motive_world_pose(
    yaw_deg: float = 37.0, translation: Sequence[float] = (1250.0, 40.0, -830.0)
) -> tuple[np.ndarray, np.ndarray]:
    """A base->mocap pose as Motive sees it: Y up, the base turned by ``yaw_deg`` about its z."""
    return Y_UP @ rotation_about_z(np.radians(yaw_deg)), np.asarray(translation, dtype=float)


def effector_offset(effector_markers: Mapping[str, Sequence[float]]) -> tuple[float, float, float]:
    """The session's ``offset``: B minus the centroid of markers given relative to B."""
    c = -np.mean(np.asarray(list(effector_markers.values()), dtype=float), axis=0)
    return (float(c[0]) + 0.0, float(c[1]) + 0.0, float(c[2]) + 0.0)


def synthesize_take(
    effector_point_base: ArrayLike,
    *,
    base_markers: Mapping[str, Sequence[float]] = DEFAULT_BASE_MARKERS,
    effector_markers: Mapping[str, Sequence[float]] = DEFAULT_EFFECTOR_MARKERS,
    mocap_pose: tuple[np.ndarray, np.ndarray] | None = None,
    noise_mm: float = 0.0,
    jitter_mm: float = 0.02,
    base_error_mm: float = 0.0,
    n_frames: int = 120,
    rate_hz: float = 120.0,
    gaps_fraction: float = 0.0,
    realism: MocapNoise | None = None,
    rng: np.random.Generator | None = None,
    path: str | os.PathLike[str] | None = None,
    format: str = "motive-csv",
    **writer_options: Any,
) -> Take:
    """Marker trajectories (mocap world, mm) of an effector at rest at ``effector_point_base``.

    ``effector_markers`` are offsets from B (base frame). ``base_error_mm``: std of a
    fixed error of each base marker's true position against its nominal one.
    ``realism`` (default: white ``jitter_mm`` and ``gaps_fraction`` single-cell gaps)
    says how the system disturbs the take. Written to ``path`` (as ``format``, with
    ``writer_options``) when given.
    """
    rng = rng if rng is not None else np.random.default_rng()
    noise = realism if realism is not None else MocapNoise.white(jitter_mm, gaps_fraction)
    rot, trans = mocap_pose if mocap_pose is not None else motive_world_pose()
    rot = np.asarray(rot, dtype=float)
    b = np.asarray(effector_point_base, dtype=float).reshape(3)
    base = np.asarray(list(base_markers.values()), dtype=float)
    base = base + rng.normal(0.0, base_error_mm, base.shape) if base_error_mm > 0 else base
    eff = b + np.asarray(list(effector_markers.values()), dtype=float)
    eff = eff + (rng.normal(0.0, noise_mm, 3) if noise_mm > 0 else 0.0)
    times = np.arange(n_frames) / rate_hz
    world = np.vstack([base, eff]) @ rot.T + np.asarray(trans, dtype=float)
    positions = np.repeat(world[None], n_frames, axis=0)
    motion = effector_motion(rng, times, rate_hz, noise) @ rot.T  # the effector really moves
    positions[:, len(base) :] += motion[:, None, :]
    if noise.jitter_mm > 0 or noise.static_mm > 0:
        positions += marker_noise(rng, n_frames, positions.shape[1], rate_hz, noise)
    positions[
        gap_mask(rng, n_frames, positions.shape[1], noise.gap_fraction, noise.gap_run_frames)
    ] = np.nan
    names = tuple(base_markers) + tuple(effector_markers)
    take = Take(names, positions, times, str(path or "<synthetic>"), format)
    if path is not None:
        write_take(path, take, format, **writer_options)
    return take


def synthetic_config(
    profile_name: str,
    format: str = "motive-csv",
    base_markers: Mapping[str, Sequence[float]] = DEFAULT_BASE_MARKERS,
    effector_markers: Mapping[str, Sequence[float]] = DEFAULT_EFFECTOR_MARKERS,
) -> SessionConfig:
    mocap = MocapConfig.model_validate(
        {
            "format": format,
            "base_markers": {k: tuple(v) for k, v in base_markers.items()},
            "effector": EffectorConfig(
                markers=tuple(effector_markers), offset=effector_offset(effector_markers)
            ),
        }
    )
    return SessionConfig.model_validate({"session": {"profile": profile_name}, "mocap": mocap})


def write_synthetic_session(
    directory: str | os.PathLike[str],
    measured_points: np.ndarray,
    commanded: np.ndarray,
    s_cmd: np.ndarray,
    t_s: np.ndarray,
    dirs: np.ndarray,
    profile_name: str,
    *,
    format: str = "motive-csv",
    noise_mm: float = 0.05,
    jitter_mm: float = 0.02,
    seed: int | None = 0,
    n_frames: int = 60,
    gaps_fraction: float = 0.0,
    rate_hz: float = 120.0,
    realism: MocapNoise | Sequence[MocapNoise] | None = None,
    base_markers: Mapping[str, Sequence[float]] = DEFAULT_BASE_MARKERS,
    effector_markers: Mapping[str, Sequence[float]] = DEFAULT_EFFECTOR_MARKERS,
    mocap_pose: tuple[np.ndarray, np.ndarray] | None = None,
    writer_options: Mapping[str, object] | None = None,
    roles: Sequence[str] | None = None,
) -> Path:
    """A whole session folder whose takes measure ``measured_points`` (K, 3) with noise.

    ``realism``: one :class:`MocapNoise` for every take, or one per take.

    Appends to an existing synthetic session of the same configuration (resume).
    """
    rng = np.random.default_rng(seed)
    pts = np.asarray(measured_points, dtype=float).reshape(-1, 3)
    k = len(pts)
    cmd = np.asarray(commanded, dtype=float).reshape(k, 3)
    sl = np.asarray(s_cmd, dtype=float).reshape(k, 3)
    times = np.asarray(t_s, dtype=float).reshape(k)
    d = np.asarray(dirs).reshape(k, 3)
    writer = SessionWriter(
        directory, synthetic_config(profile_name, format, base_markers, effector_markers)
    )
    pose = mocap_pose if mocap_pose is not None else motive_world_pose()
    for i in range(k):
        take = synthesize_take(
            pts[i],
            base_markers=base_markers,
            effector_markers=effector_markers,
            mocap_pose=pose,
            noise_mm=noise_mm,
            jitter_mm=jitter_mm,
            n_frames=n_frames,
            rate_hz=rate_hz,
            gaps_fraction=gaps_fraction,
            realism=realism if realism is None or isinstance(realism, MocapNoise) else realism[i],
            rng=rng,
        )
        writer.add_take(
            take,
            t_s=times[i],
            commanded=cmd[i],
            s_cmd=sl[i],
            dirs=d[i],
            format=format,
            extra=None if roles is None else {"role": roles[i]},
            **dict(writer_options or {}),
        )
    return Path(directory)


@dataclass(frozen=True, eq=False)
class MeasuredSession:
    directory: Path
    actual: np.ndarray  # (K, 3) where the true effector was at each pose (base frame, mm)
    s_cmd: np.ndarray  # (K, 3) commanded sliders
    crept: np.ndarray  # (K,) bool: the take crept


def write_measured_session(
    directory: str | os.PathLike[str],
    truth: MachineModel,
    nominal: MachineModel,
    poses: np.ndarray,
    t_s: np.ndarray,
    *,
    realism: MocapNoise,
    rate_hz: float = 240.0,
    duration_s: float = 3.0,
    creep_probability: float = 0.0,
    format: str = "motive-csv",
    profile_name: str = "paper-simulation",
    roles: Sequence[str] | None = None,
    seed: int = 0,
    writer_options: Mapping[str, object] | None = None,
) -> MeasuredSession:
    """A session folder of ``poses`` commanded through ``nominal`` (visiting order) on the
    ``truth`` machine and recorded by a realistic motion capture: every take its own draw of
    settling and, with ``creep_probability``, a creep (:func:`~.mocap_noise.vary`).
    Returns where the effector really was and which takes crept."""
    rng = np.random.default_rng(seed)
    pts = np.asarray(poses, dtype=float).reshape(-1, 3)
    times = np.asarray(t_s, dtype=float).reshape(-1)
    s_cmd, dirs = commanded_path(nominal, pts)
    actual = truth.fk(s_cmd, MotionContext(t_s=times, directions=dirs))
    noises = [vary(realism, rng, creep_probability=creep_probability) for _ in range(len(pts))]
    write_synthetic_session(
        directory,
        actual,
        pts,
        s_cmd,
        times,
        dirs.astype(int),
        profile_name,
        format=format,
        noise_mm=0.0,
        seed=int(rng.integers(2**31)),
        n_frames=max(int(round(duration_s * rate_hz)), 2),
        rate_hz=rate_hz,
        realism=noises,
        writer_options=writer_options,
        roles=roles,
    )
    return MeasuredSession(
        Path(directory), actual, s_cmd, np.array([n.creep_mm > 0 for n in noises])
    )
