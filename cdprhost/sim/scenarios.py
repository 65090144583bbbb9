"""Hidden-effect scenarios: a true machine with one effect the host does not know,
and a realistic measurement session of it (array level; files via the synthetic
session writer).

Magnitudes (per module where the effect has one parameter per module, random
sign where the sign is not physical): EA 15-25 kN; |eps| 0.3-0.8 %; half-lash
0.15-0.3 mm; |rho| 0.2-0.5 um/s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cdprhost.calibration.fitting import Observations
from cdprhost.effects.base import Effect
from cdprhost.effects.registry import CATALOGUE, EffectChain
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.measurement import perturbed_geometry, simulate_observations

MAGNITUDES: dict[str, tuple[float, float]] = {
    "cable_elasticity": (15000.0, 25000.0),  # EA, N
    "drive_scale": (0.003, 0.008),  # |eps|
    "backlash": (0.15, 0.30),  # half lash, mm
    "drift": (0.2e-3, 0.5e-3),  # |rho|, mm/s
}


def random_effect_vector(name: str, rng: np.random.Generator) -> np.ndarray:
    """A fitting vector for a catalogue effect at a realistic magnitude."""
    lo, hi = MAGNITUDES[name]
    if name == "cable_elasticity":
        return np.array([1.0 / rng.uniform(lo, hi)])
    mag = rng.uniform(lo, hi, 3)
    if name == "backlash":
        return mag
    return np.asarray(mag * rng.choice([-1.0, 1.0], 3))


def measurement_tour(
    model: MachineModel, n_poses: int, rng: np.random.Generator, margin_mm: float = 5.0
) -> np.ndarray:
    """``n_poses`` points spread over the build volume (uniform in the triangle and in z,
    all inside the workspace), in a shuffled visiting order so approach directions vary."""
    lim = model.limits
    side = lim.build_side - 2 * margin_mm * np.sqrt(3.0)
    out: list[np.ndarray] = []
    count = 0
    while count < n_poses:
        m = 4 * n_poses
        xy = np.column_stack(
            [
                rng.uniform(-side / 2, side / 2, m),
                rng.uniform(-side / (2 * np.sqrt(3)), side / np.sqrt(3), m),
            ]
        )
        z = rng.uniform(lim.z_min + margin_mm, lim.z_max - margin_mm, m)
        pts = np.column_stack([xy, z])
        pts = pts[model.check(pts).ok]
        out.append(pts)
        count += len(pts)
    pts = np.concatenate(out)[:n_poses]
    return pts[rng.permutation(n_poses)]


def session_times(
    n_poses: int, rng: np.random.Generator, seconds: tuple[float, float] = (20.0, 60.0)
) -> np.ndarray:
    """Take start times: 20-60 s between poses."""
    return np.cumsum(rng.uniform(*seconds, n_poses))


def hidden_truth(
    nominal: MachineModel,
    rng: np.random.Generator,
    effect: str | Effect | Sequence[str | Effect] | None,
    vector: np.ndarray | Sequence[np.ndarray | None] | None = None,
    geometry_mm: float = 2.0,
) -> MachineModel:
    """The true machine: geometry off the nominal by up to ``geometry_mm`` per parameter,
    plus hidden effects: a catalogue name, any Effect object outside the catalogue, or a
    sequence of them (several at once); ``vector`` gives their vectors (default: random,
    realistic magnitudes)."""
    geometry = perturbed_geometry(nominal.geometry, rng, geometry_mm)
    if effect is None:
        return nominal.with_geometry(geometry, EffectChain())
    effects: list[str | Effect] = [effect] if isinstance(effect, (str, Effect)) else list(effect)
    several = not isinstance(effect, (str, Effect))
    vectors: list[np.ndarray | None] = (
        [None if v is None else np.asarray(v, float) for v in vector]
        if several and vector is not None
        else [None if vector is None else np.asarray(vector, float)] * len(effects)
    )
    objs: list[Effect] = [CATALOGUE[e] if isinstance(e, str) else e for e in effects]
    vecs = [
        random_effect_vector(o.name, rng) if v is None else np.asarray(v, float)
        for o, v in zip(objs, vectors)
    ]
    return nominal.with_geometry(geometry, EffectChain(tuple(objs), tuple(vecs)))


def simulate_session(
    truth: MachineModel,
    nominal: MachineModel,
    rng: np.random.Generator,
    n_poses: int = 40,
    noise_mm: float = 0.05,
) -> tuple[np.ndarray, Observations]:
    """Commanded poses and the observations of one simulated session.

    Near z_min the cables are almost horizontal, so a few millimetres of geometry
    error can leave the true machine with no three-sphere solution at a commanded
    pose; such a session is drawn again (rare)."""
    for _ in range(20):
        poses = measurement_tour(nominal, n_poses, rng)
        obs = simulate_observations(
            truth, nominal, poses, noise_mm=noise_mm, rng=rng, t_s=session_times(n_poses, rng)
        )
        if np.isfinite(obs.measured).all():
            break
    return poses, obs
