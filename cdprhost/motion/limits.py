"""Per-move speed and acceleration caps, and the chord length for segmentation.

Cartesian limits come from the profile (max velocity, max acceleration, never above
the statics' a_max that the tension check assumes). Module limits go through the
velocity Jacobian: along a straight move with unit direction u, module k's slider
moves at ds_k/dt = c_k v with c_k = e_k . u (e_k the unit cable vector) and
accelerates at c_k a + kappa_k v^2 with kappa_k = (1 - c_k^2) / L_k. Each move is
sampled at its ends and every 10 mm in between; between samples c_k changes by at
most kappa_k per mm, which bounds the unsampled part. The speed cap keeps
kappa_k v^2 within 3/4 of the module acceleration; the acceleration cap spends
what is left on c_k a.

Chord length: interpolating the sliders linearly between two points h apart on
the line misses the line's midpoint by about h^2/8 |J^-1 kappa|, so pieces of
length sqrt(8 tol / |J^-1 kappa|) stay within tol of the line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.motion.moves import MIN_MOVE_MM, MoveBlock
from cdprhost.profile.models import Extruder, MachineProfile, MotionLimits

Vec3 = tuple[np.ndarray, np.ndarray, np.ndarray]  # one array per coordinate

#: spacing of the Jacobian samples along a move (mm)
SAMPLE_SPACING_MM = 10.0
#: at most this many samples inside one move (moves longer than 40 cm, more than this
#: kind of machine can make, are sampled more sparsely: their bound is looser, never
#: wrong); moves longer than ``ABSURD_MOVE_MM`` (a typo: preflight refuses them) get 4
MAX_SAMPLES_PER_MOVE = 40
ABSURD_MOVE_MM = 2000.0
#: fraction of the chord tolerance the segment length aims for (rest: higher order terms)
CHORD_SAFETY = 0.7


@dataclass(frozen=True)
class Caps:
    """What :func:`move_caps` works with, from a profile."""

    max_velocity: float
    max_accel: float
    junction_deviation: float
    module_velocity: float
    module_accel: float
    chord_tolerance: float
    e_velocity: float
    e_accel: float
    #: the board's step budget (steps/s summed over the axes; inf: none) and what each
    #: axis steps per mm (modules, extruder) to spend it
    total_step_rate: float = float("inf")
    module_steps_per_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    e_steps_per_mm: float = 0.0

    @classmethod
    def for_profile(cls, profile: MachineProfile, *, module_limits: bool = True) -> Caps:
        """A profile's limits as a move plan keeps them: Cartesian, statics, modules and
        the board's step budget (``motion.max_total_step_rate``, spent through the modules'
        steps per mm)."""
        return cls.from_profile(
            profile.motion,
            profile.extruder,
            profile.statics.a_max_mm_s2,
            module_limits=module_limits,
            steps_per_mm=profile.drive.steps_per_mm,
        )

    @classmethod
    def from_profile(
        cls,
        motion: MotionLimits,
        extruder: Extruder,
        a_max_statics: float = 0.0,
        *,
        module_limits: bool = True,
        steps_per_mm: tuple[float, float, float] | None = None,
    ) -> Caps:
        """``steps_per_mm`` (the modules', ``profile.drive``): with it, the motion's
        ``max_total_step_rate`` caps each move's speed (without it the budget is left out)."""
        accel = (
            motion.max_accel_mm_s2
            if a_max_statics <= 0
            else min(motion.max_accel_mm_s2, a_max_statics)
        )
        inf = float("inf")
        total, spm = inf, (0.0, 0.0, 0.0)
        if steps_per_mm is not None and motion.max_total_step_rate is not None:
            total = motion.max_total_step_rate
            spm = (float(steps_per_mm[0]), float(steps_per_mm[1]), float(steps_per_mm[2]))
        return cls(
            motion.max_velocity_mm_s,
            accel,
            motion.junction_deviation_mm,
            motion.module_max_velocity_mm_s if module_limits else inf,
            motion.module_max_accel_mm_s2 if module_limits else inf,
            motion.chord_tolerance_mm,
            extruder.max_velocity_mm_s,
            extruder.max_accel_mm_s2,
            total,
            spm,
            extruder.steps_per_mm,
        )


@dataclass(frozen=True)
class MoveCaps:
    """Per move: path length (Cartesian, or filament for extrude-only moves) and limits."""

    length: np.ndarray  # (n,) mm
    kinematic: np.ndarray  # (n,) bool: the effector moves
    unit: np.ndarray  # (n, 3) direction (zeros for extrude-only)
    accel: np.ndarray  # (n,) mm/s^2
    v2_cap: np.ndarray  # (n,) (mm/s)^2, all limits
    v2_cartesian: np.ndarray  # (n,) (mm/s)^2, feedrate and Cartesian/extruder limits only
    chord_step: (
        np.ndarray
    )  # (n,) mm, longest piece within the chord tolerance (inf: no Cartesian motion)

    @property
    def module_limited(self) -> np.ndarray:
        """Moves the module limits slow below their (capped) feedrate."""
        return self.v2_cap < self.v2_cartesian * (1.0 - 1e-9)


def _max3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(a, b), c)


@dataclass(frozen=True)
class _PointTerms:
    """Direction-independent cable terms at points (structure of arrays, cable k in [k])."""

    e: tuple[Vec3, ...]  # e[k] = (ex, ey, ez) unit vector from outlet k
    inv_length: tuple[np.ndarray, ...]  # 1 / L_k
    cof: tuple[Vec3, ...] | None  # columns of adj(J) (e2 x e3, e3 x e1, e1 x e2) / det J

    @classmethod
    def at(
        cls, x: np.ndarray, y: np.ndarray, z: np.ndarray, outlets: np.ndarray, chord: bool
    ) -> _PointTerms:
        e, inv = [], []
        for k in range(3):  # three cables, each vectorised over points
            dx, dy, dz = x - outlets[k, 0], y - outlets[k, 1], z - outlets[k, 2]
            il = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
            e.append((dx * il, dy * il, dz * il))
            inv.append(il)
        cof = None
        if chord:

            def cross(a: Vec3, b: Vec3) -> Vec3:
                return (
                    a[1] * b[2] - a[2] * b[1],
                    a[2] * b[0] - a[0] * b[2],
                    a[0] * b[1] - a[1] * b[0],
                )

            c23, c31, c12 = cross(e[1], e[2]), cross(e[2], e[0]), cross(e[0], e[1])
            inv_det = 1.0 / (e[0][0] * c23[0] + e[0][1] * c23[1] + e[0][2] * c23[2])
            cof = tuple(
                (col[0] * inv_det, col[1] * inv_det, col[2] * inv_det) for col in (c23, c31, c12)
            )
        return cls(tuple(e), tuple(inv), cof)

    def take(self, idx: slice | np.ndarray) -> _PointTerms:
        def pick3(t: Vec3) -> Vec3:
            return (t[0][idx], t[1][idx], t[2][idx])

        return _PointTerms(
            tuple(pick3(v) for v in self.e),
            tuple(a[idx] for a in self.inv_length),
            None if self.cof is None else tuple(pick3(c) for c in self.cof),
        )

    def along(
        self,
        ux: np.ndarray,
        uy: np.ndarray,
        uz: np.ndarray,
        steps_per_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
        """max_k |c_k|, max_k kappa_k, |J^-1 kappa| and sum_k |c_k| n_k (the modules'
        steps per mm of path, ``steps_per_mm`` n_k) for moves of direction u through these
        points."""
        c, kap = [], []
        steps = np.zeros_like(ux)
        for k in range(3):
            ex, ey, ez = self.e[k]
            ck = ex * ux + ey * uy + ez * uz
            c.append(np.abs(ck))
            kap.append((1.0 - ck * ck) * self.inv_length[k])
            if steps_per_mm[k]:
                steps = steps + c[k] * steps_per_mm[k]
        w = None
        if self.cof is not None:
            comps = [
                kap[0] * self.cof[0][i] + kap[1] * self.cof[1][i] + kap[2] * self.cof[2][i]
                for i in range(3)
            ]
            w = np.sqrt(comps[0] * comps[0] + comps[1] * comps[1] + comps[2] * comps[2])
        return _max3(*c), _max3(*kap), w, steps


def _interior_samples(
    dist: np.ndarray, spacing: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Interior sample points of moves longer than ``spacing``: (move index, fraction)."""
    inner = np.floor(dist / spacing).astype(np.int64)  # samples strictly inside each move
    owner = np.repeat(np.arange(dist.shape[0]), inner)
    first = np.cumsum(inner) - inner
    j = np.arange(owner.shape[0]) - first[owner] + 1
    return owner, j / (inner[owner] + 1.0)


def move_caps(block: MoveBlock, outlets: np.ndarray, caps: Caps, *, chord: bool = True) -> MoveCaps:
    """Length, acceleration, cruise-speed cap and chord step of every move (vectorised).

    ``chord=False`` skips the chord step (``inf``), for planning time estimates only.
    """
    n = len(block)
    delta = block.delta
    dx, dy, dz = delta[:, 0], delta[:, 1], delta[:, 2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    de = np.abs(block.extrusion)
    kin = dist > MIN_MOVE_MM
    length = np.where(kin, dist, de)
    inv = np.where(kin, 1.0 / np.where(kin, dist, 1.0), 0.0)
    ux, uy, uz = dx * inv, dy * inv, dz * inv
    feed = np.maximum(block.feedrate, 1e-9)

    # extruder-only moves: the extruder's own limits; kinematic moves: Cartesian,
    # and the extruder limits scaled by its share of the motion
    ratio = np.where(kin, de * inv, 1.0)
    with np.errstate(divide="ignore", over="ignore"):  # (a vanishing share: no limit)
        e_v = np.where(ratio > 0, caps.e_velocity / ratio, np.inf)
        e_a = np.where(ratio > 0, caps.e_accel / ratio, np.inf)
    v_cart = np.minimum(feed, np.where(kin, np.minimum(caps.max_velocity, e_v), caps.e_velocity))
    accel = np.where(kin, np.minimum(caps.max_accel, e_a), caps.e_accel)
    if block.accel_limit is not None:
        accel = np.minimum(accel, block.accel_limit)
    v2_cart = v_cart * v_cart
    v2_cap = v2_cart.copy()
    chord_step = np.full(n, np.inf)
    unit = np.column_stack([ux, uy, uz])
    budget = np.isfinite(caps.total_step_rate)
    if budget and caps.e_steps_per_mm > 0:  # extrude-only moves: the extruder spends it all
        v2_cap = np.where(
            kin, v2_cap, np.minimum(v2_cap, (caps.total_step_rate / caps.e_steps_per_mm) ** 2)
        )
    modules = np.isfinite(caps.module_velocity) or np.isfinite(caps.module_accel) or budget
    if not (kin.any() and (modules or chord)):
        return MoveCaps(length, kin, unit, accel, v2_cap, v2_cart, chord_step)

    # endpoints: shared between consecutive moves when the block is a continuous path
    chained = n > 1 and np.array_equal(block.start[1:], block.end[:-1])
    pts = (
        np.vstack([block.start[:1], block.end]) if chained else np.vstack([block.start, block.end])
    )
    terms = _PointTerms.at(pts[:, 0], pts[:, 1], pts[:, 2], outlets, chord)
    i0 = slice(0, n)  # views, not copies
    i1 = slice(1, n + 1) if chained else slice(n, 2 * n)
    spm = caps.module_steps_per_mm
    c0, k0, w0, s0 = terms.take(i0).along(ux, uy, uz, spm)
    c1, k1, w1, s1 = terms.take(i1).along(ux, uy, uz, spm)
    c_max, k_max, s_max = np.maximum(c0, c1), np.maximum(k0, k1), np.maximum(s0, s1)
    w_max = np.maximum(w0, w1) if w0 is not None and w1 is not None else None
    spacing_req = np.maximum(SAMPLE_SPACING_MM, dist / MAX_SAMPLES_PER_MOVE)
    spacing_req = np.where(dist > ABSURD_MOVE_MM, dist / 4.0, spacing_req)
    owner, frac = _interior_samples(np.where(kin, dist, 0.0), spacing_req)
    if owner.size:
        p = block.start[owner] + frac[:, None] * delta[owner]
        ci, ki, wi, si = _PointTerms.at(p[:, 0], p[:, 1], p[:, 2], outlets, chord).along(
            ux[owner], uy[owner], uz[owner], spm
        )
        np.maximum.at(c_max, owner, ci)
        np.maximum.at(k_max, owner, ki)
        np.maximum.at(s_max, owner, si)
        if w_max is not None and wi is not None:
            np.maximum.at(w_max, owner, wi)
    spacing = dist / (np.floor(dist / spacing_req) + 1.0)
    c_bound = np.clip(c_max + 0.5 * k_max * spacing, 1e-9, 1.0)  # >0: three cables span space
    k_bound = k_max * 1.05 + 1e-12
    # module speed, then keep the J-dot term within 3/4 of the module acceleration
    v2_mod = np.minimum((caps.module_velocity / c_bound) ** 2, 0.75 * caps.module_accel / k_bound)
    v2_cap = np.where(kin, np.minimum(v2_cap, v2_mod), v2_cap)
    if budget:
        # the board's budget: the modules' steps per mm of path (each |c_k| moves by at
        # most kappa_k per mm between samples) and the extruder's share of it
        s_bound = s_max + 0.5 * k_max * spacing * sum(spm)
        v_total = caps.total_step_rate / np.maximum(s_bound + ratio * caps.e_steps_per_mm, 1e-12)
        v2_cap = np.where(kin, np.minimum(v2_cap, v_total * v_total), v2_cap)
    a_mod = (caps.module_accel - v2_cap * k_bound) / c_bound
    accel = np.where(kin, np.minimum(accel, a_mod), accel)
    if w_max is not None:
        step = np.sqrt(8.0 * caps.chord_tolerance * CHORD_SAFETY / np.maximum(w_max * 1.05, 1e-12))
        chord_step = np.where(kin, step, np.inf)
    return MoveCaps(length, kin, unit, accel, v2_cap, v2_cart, chord_step)
