"""Synthetic motion-capture takes and whole session folders (virtual mocap, tests, benchmarks).

The effector does not rotate (a cable robot of this kind translates only), so its
markers sit at fixed offsets from the effector point B, given in the base frame.
Markers are placed in the base frame, carried into the mocap world by
``mocap_pose`` (R, t: ``x_mocap = R x_base + t``; Motive's world is Y-up), and
disturbed by two noises:

- ``noise_mm``: one static offset per take, per coordinate, on the effector
  markers. Averaging over frames leaves it intact, so it is the std of the final
  measured point, as the calibration benchmark's "mocap noise" means.
- ``jitter_mm``: independent per frame and marker; averaging shrinks it by
  sqrt(frames * markers), so it barely moves the measured point.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from cdprhost.calibration.readers import Take, write_take
from cdprhost.calibration.registration import rotation_about_z
from cdprhost.calibration.session import SessionConfig, SessionWriter
from cdprhost.calibration.takes import EffectorConfig, MocapConfig

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
    return tuple(
        float(v) + 0.0
        for v in -np.mean(np.asarray(list(effector_markers.values()), dtype=float), axis=0)
    )


def synthesize_take(
    effector_point_base: Sequence[float],
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
    rng: np.random.Generator | None = None,
    path: str | os.PathLike[str] | None = None,
    format: str = "motive-csv",
    **writer_options,
) -> Take:
    """Marker trajectories (mocap world, mm) of a static effector at ``effector_point_base``.

    ``effector_markers`` are offsets from B (base frame). ``base_error_mm``: std of a
    fixed error of each base marker's true position against its nominal one.
    ``gaps_fraction`` of (frame, marker) cells become gaps. Written to ``path`` (as
    ``format``, with ``writer_options``) when given.
    """
    rng = rng if rng is not None else np.random.default_rng()
    rot, trans = mocap_pose if mocap_pose is not None else motive_world_pose()
    b = np.asarray(effector_point_base, dtype=float).reshape(3)
    base = np.asarray(list(base_markers.values()), dtype=float)
    base = base + rng.normal(0.0, base_error_mm, base.shape) if base_error_mm > 0 else base
    eff = b + np.asarray(list(effector_markers.values()), dtype=float)
    eff = eff + (rng.normal(0.0, noise_mm, 3) if noise_mm > 0 else 0.0)
    world = np.vstack([base, eff]) @ np.asarray(rot, dtype=float).T + np.asarray(trans, dtype=float)
    positions = np.repeat(world[None], n_frames, axis=0)
    if jitter_mm > 0:
        positions = positions + rng.normal(0.0, jitter_mm, positions.shape)
    if gaps_fraction > 0:
        positions[rng.random(positions.shape[:2]) < gaps_fraction] = np.nan
    names = tuple(base_markers) + tuple(effector_markers)
    take = Take(names, positions, np.arange(n_frames) / rate_hz, str(path or "<synthetic>"), format)
    if path is not None:
        write_take(path, take, format, **writer_options)
    return take


def synthetic_config(
    profile_name: str,
    format: str = "motive-csv",
    base_markers: Mapping[str, Sequence[float]] = DEFAULT_BASE_MARKERS,
    effector_markers: Mapping[str, Sequence[float]] = DEFAULT_EFFECTOR_MARKERS,
) -> SessionConfig:
    mocap = MocapConfig(
        format=format,
        base_markers={k: tuple(v) for k, v in base_markers.items()},
        effector=EffectorConfig(
            markers=tuple(effector_markers), offset=effector_offset(effector_markers)
        ),
    )
    return SessionConfig(session={"profile": profile_name}, mocap=mocap)


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
    base_markers: Mapping[str, Sequence[float]] = DEFAULT_BASE_MARKERS,
    effector_markers: Mapping[str, Sequence[float]] = DEFAULT_EFFECTOR_MARKERS,
    mocap_pose: tuple[np.ndarray, np.ndarray] | None = None,
    writer_options: Mapping[str, object] | None = None,
) -> Path:
    """A whole session folder whose takes measure ``measured_points`` (K, 3) with noise.

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
            gaps_fraction=gaps_fraction,
            rng=rng,
        )
        writer.add_take(
            take,
            t_s=times[i],
            commanded=cmd[i],
            s_cmd=sl[i],
            dirs=d[i],
            format=format,
            **dict(writer_options or {}),
        )
    return Path(directory)
