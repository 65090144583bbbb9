"""What a real optical motion-capture system adds to a static scene, as arrays.

A take of a cable robot at rest is not a constant plus white noise:

- **jitter** of each marker is autocorrelated (camera exposure, marker centroiding and
  the system's own smoothing): AR(1) with a correlation time, and each marker has its
  own level (small or far markers are noisier: a log-normal factor per marker);
- the effector **hums** on its cables: a band-limited motion common to its markers;
- after each move it **settles**: a damped oscillation in a random direction;
- now and then it **creeps** slowly (cable creep, a slipping pulley): a linear drift;
- markers drop out in **runs** of frames (occlusion), not single cells;
- optionally a **static** error per marker and take that no averaging removes.

Everything is vectorised over frames and markers; the caller owns the random generator.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.signal import butter, lfilter, lfilter_zi


@dataclass(frozen=True)
class MocapNoise:
    """Disturbances of one take (lengths in mm, times in s, rates in Hz)."""

    jitter_mm: float = 0.1
    correlation_s: float = 0.015
    marker_variation: float = 0.3
    hum_mm: float = 0.0
    hum_band_hz: tuple[float, float] = (2.0, 8.0)
    settle_mm: float = 0.0
    settle_hz: float = 3.0
    settle_decay_s: float = 0.25
    creep_mm: float = 0.0
    gap_fraction: float = 0.0
    gap_run_frames: float = 10.0
    static_mm: float = 0.0
    creep_direction: tuple[float, float, float] | None = field(default=None)

    @classmethod
    def white(cls, jitter_mm: float, gap_fraction: float = 0.0) -> MocapNoise:
        """Independent frame noise and single-cell gaps (the simplest model)."""
        return cls(
            jitter_mm=jitter_mm,
            correlation_s=0.0,
            marker_variation=0.0,
            gap_fraction=gap_fraction,
            gap_run_frames=1.0,
        )


def ar1_noise(
    rng: np.random.Generator, shape: tuple[int, ...], rho: float, sigma: np.ndarray | float
) -> np.ndarray:
    """Stationary AR(1) series along axis 0 with lag-1 correlation ``rho`` and std ``sigma``."""
    white = rng.normal(0.0, 1.0, shape)
    if rho <= 0.0:
        return white * sigma
    innov = white * np.sqrt(1.0 - rho * rho)
    innov[0] = white[0]  # the stationary start
    return np.asarray(lfilter([1.0], [1.0, -rho], innov, axis=0)) * sigma


def band_limited(
    rng: np.random.Generator,
    n: int,
    rate_hz: float,
    band_hz: tuple[float, float],
    sigma: float,
    dims: int = 3,
) -> np.ndarray:
    """Gaussian noise in ``band_hz`` (second-order Butterworth band-pass), std ``sigma``, (n, dims)."""
    nyq = rate_hz / 2.0
    lo, hi = band_hz[0] / nyq, min(band_hz[1] / nyq, 0.95)
    if n < 2 or sigma <= 0 or lo >= hi:
        return np.zeros((n, dims))
    b, a = butter(2, [lo, hi], btype="band")
    warm = int(4 * rate_hz / max(band_hz[0], 0.1))
    raw = rng.normal(0.0, 1.0, (n + warm, dims))
    out = lfilter(b, a, raw, axis=0, zi=lfilter_zi(b, a)[:, None] * raw[:1])[0][warm:]
    std = float(np.std(out)) or 1.0
    return np.asarray(out) / std * sigma


def random_direction(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def effector_motion(
    rng: np.random.Generator, times_s: np.ndarray, rate_hz: float, noise: MocapNoise
) -> np.ndarray:
    """How the effector really moves during a take, (n, 3): settling swing + creep + hum."""
    t = np.asarray(times_s, dtype=float) - float(times_s[0])
    out = np.zeros((t.size, 3))
    if noise.settle_mm > 0:
        phase = rng.uniform(0, 2 * np.pi)
        swing = np.exp(-t / noise.settle_decay_s) * np.cos(2 * np.pi * noise.settle_hz * t + phase)
        out += noise.settle_mm * swing[:, None] * random_direction(rng)
    if noise.creep_mm > 0 and t.size > 1:
        d = (
            random_direction(rng)
            if noise.creep_direction is None
            else np.asarray(noise.creep_direction) / np.linalg.norm(noise.creep_direction)
        )
        out += noise.creep_mm * (t / t[-1])[:, None] * d
    if noise.hum_mm > 0:
        out += band_limited(rng, t.size, rate_hz, noise.hum_band_hz, noise.hum_mm)
    return out


def marker_noise(
    rng: np.random.Generator, n_frames: int, n_markers: int, rate_hz: float, noise: MocapNoise
) -> np.ndarray:
    """Per-marker measurement error, (n_frames, n_markers, 3): AR(1) jitter at each marker's
    own level, plus a static error per marker."""
    level = noise.jitter_mm * np.exp(noise.marker_variation * rng.normal(size=n_markers))
    rho = float(np.exp(-1.0 / (rate_hz * noise.correlation_s))) if noise.correlation_s > 0 else 0.0
    out = ar1_noise(rng, (n_frames, n_markers, 3), rho, level[None, :, None])
    if noise.static_mm > 0:
        out += rng.normal(0.0, noise.static_mm, (1, n_markers, 3))
    return out


def gap_mask(
    rng: np.random.Generator, n_frames: int, n_markers: int, fraction: float, mean_run: float
) -> np.ndarray:
    """(n_frames, n_markers) True where a marker is lost: runs of geometric length with mean
    ``mean_run`` frames, started so that about ``fraction`` of the cells are lost."""
    if fraction <= 0 or n_frames == 0:
        return np.zeros((n_frames, n_markers), dtype=bool)
    run = max(float(mean_run), 1.0)
    if run <= 1.0:
        return rng.random((n_frames, n_markers)) < fraction
    p_start = min(fraction / (run * (1.0 - fraction) + fraction), 1.0)
    starts = rng.random((n_frames, n_markers)) < p_start
    lengths = rng.geometric(1.0 / run, size=(n_frames, n_markers))
    # each frame is lost if some run started within the last L frames covers it
    end = np.where(starts, np.arange(n_frames)[:, None] + lengths, -1)
    covered_until = np.maximum.accumulate(end, axis=0)
    return np.asarray(covered_until > np.arange(n_frames)[:, None])


def vary(
    noise: MocapNoise,
    rng: np.random.Generator,
    *,
    creep_probability: float = 0.0,
    creep_mm: tuple[float, float] = (0.15, 0.4),
) -> MocapNoise:
    """One take's disturbances: the system's ``noise`` with the settling swing drawn afresh
    (amplitude x U(0.5, 1.5), frequency x U(0.7, 1.3)) and, with ``creep_probability``, a
    creep of U(``creep_mm``) over the take."""
    creep = float(rng.uniform(*creep_mm)) if rng.random() < creep_probability else noise.creep_mm
    return replace(
        noise,
        settle_mm=noise.settle_mm * float(rng.uniform(0.5, 1.5)),
        settle_hz=noise.settle_hz * float(rng.uniform(0.7, 1.3)),
        creep_mm=creep,
    )


def effector_series(
    rng: np.random.Generator,
    n_takes: int,
    n_frames: int,
    rate_hz: float,
    noise: MocapNoise,
    *,
    n_markers: int = 3,
    creep_mm: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Per-frame effector points (n_takes, n_frames, 3) of many takes of a static effector at
    the origin, as the take test sees them (the centroid of ``n_markers`` effector markers,
    registration aside): marker jitter, settling swing, hum, gaps and a creep of ``creep_mm``
    (per take) in a random direction. Vectorised over takes (for Monte Carlo)."""
    t = np.arange(n_frames) / rate_hz
    level = noise.jitter_mm * np.exp(noise.marker_variation * rng.normal(size=(n_takes, n_markers)))
    rho = float(np.exp(-1.0 / (rate_hz * noise.correlation_s))) if noise.correlation_s > 0 else 0.0
    jitter = ar1_noise(rng, (n_frames, n_takes, n_markers, 3), rho, level[None, :, :, None])
    lost = gap_mask(rng, n_frames, n_takes * n_markers, noise.gap_fraction, noise.gap_run_frames)
    jitter[lost.reshape(n_frames, n_takes, n_markers)] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames with every marker lost
        x: np.ndarray = np.moveaxis(np.nanmean(jitter, axis=2), 0, 1)  # (takes, frames, 3)

    def directions() -> np.ndarray:
        d = rng.normal(size=(n_takes, 3))
        return np.asarray(d / np.linalg.norm(d, axis=1, keepdims=True))

    if noise.settle_mm > 0:
        amp = noise.settle_mm * rng.uniform(0.5, 1.5, n_takes)
        hz = noise.settle_hz * rng.uniform(0.7, 1.3, n_takes)
        phase = rng.uniform(0, 2 * np.pi, n_takes)
        swing = np.exp(-t[None] / noise.settle_decay_s) * np.cos(
            2 * np.pi * hz[:, None] * t[None] + phase[:, None]
        )
        x += (amp[:, None] * swing)[..., None] * directions()[:, None, :]
    creep = np.broadcast_to(np.asarray(creep_mm, dtype=float), (n_takes,))
    if np.any(creep > 0) and n_frames > 1:
        x += (creep[:, None] * t[None] / t[-1])[..., None] * directions()[:, None, :]
    if noise.hum_mm > 0:
        hum = band_limited(rng, n_frames, rate_hz, noise.hum_band_hz, noise.hum_mm, 3 * n_takes)
        x += np.moveaxis(hum.reshape(n_frames, n_takes, 3), 0, 1)
    return x
