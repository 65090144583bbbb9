"""The machine model: a profile's geometry, statics and effects bound together.

This is what the rest of the program calls: ``ik`` (points -> commanded slider
displacements, effects compensated), ``steps``, ``fk`` (commanded displacements ->
where the effector really goes, effects predicted), ``check``. With no effects in
the profile it is exactly the ideal model of spec/machine-model.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.effects.backlash import path_directions
from cdprhost.effects.base import MotionContext
from cdprhost.effects.registry import EffectChain
from cdprhost.kinematics.geometry import CableGeometry, cable_lengths, fk_from_lengths
from cdprhost.kinematics.statics import StaticsParams, tensions
from cdprhost.kinematics.workspace import WorkspaceLimits, WorkspaceReport, check_workspace
from cdprhost.profile.models import MachineProfile

_NO_CONTEXT = MotionContext()


@dataclass(frozen=True)
class MachineModel:
    geometry: CableGeometry
    statics: StaticsParams
    effects: EffectChain
    steps_per_mm: np.ndarray  # (3,)
    limits: WorkspaceLimits

    @classmethod
    def from_profile(
        cls, profile: MachineProfile, *, effects: EffectChain | None = None
    ) -> MachineModel:
        geometry = CableGeometry(
            np.asarray(profile.geometry.outlets, dtype=float),
            np.asarray(profile.geometry.initial_lengths, dtype=float),
        )
        statics = StaticsParams.from_profile(profile.statics)
        bv = profile.build_volume
        limits = WorkspaceLimits(
            geometry.outlets,
            statics,
            np.asarray(profile.drive.travel_mm, dtype=float),
            bv.side_mm,
            bv.z_min_mm,
            bv.z_max_mm,
        )
        chain = EffectChain.from_tables(profile.effects) if effects is None else effects
        return cls(
            geometry, statics, chain, np.asarray(profile.drive.steps_per_mm, dtype=float), limits
        )

    def with_geometry(
        self, geometry: CableGeometry, effects: EffectChain | None = None
    ) -> MachineModel:
        limits = WorkspaceLimits(
            geometry.outlets,
            self.statics,
            self.limits.travel,
            self.limits.build_side,
            self.limits.z_min,
            self.limits.z_max,
        )
        return MachineModel(
            geometry,
            self.statics,
            self.effects if effects is None else effects,
            self.steps_per_mm,
            limits,
        )

    @property
    def ideal(self) -> bool:
        return not self.effects.effects

    # ---------------------------------------------------------------- inverse
    def ik(
        self, points: np.ndarray, ctx: MotionContext | None = None, *, path: bool = False
    ) -> np.ndarray:
        """Commanded slider displacements (N, 3) that put the effector at ``points``.

        ``path=True`` treats the points as a path in order: backlash compensation
        then uses each module's direction of travel along it (unless ``ctx`` gives
        directions).
        """
        p = np.asarray(points, dtype=float)
        lengths = cable_lengths(p, self.geometry.outlets)
        if self.ideal:
            return lengths - self.geometry.initial_lengths
        if self.effects.has_cable_stage:
            lengths = self.effects.unstretch(
                lengths, tensions(p, self.geometry.outlets, self.statics)
            )
        s_act = lengths - self.geometry.initial_lengths
        ctx = ctx or _NO_CONTEXT
        if path and ctx.directions is None and "backlash" in self.effects.names:
            ctx = MotionContext(t_s=ctx.t_s, directions=path_directions(s_act))
        return self.effects.slider_inverse(s_act, ctx)

    def steps(self, sliders: np.ndarray) -> np.ndarray:
        """Absolute motor steps n_k = round(s_k * steps_per_mm_k), int64."""
        return np.rint(np.asarray(sliders, dtype=float) * self.steps_per_mm).astype(np.int64)

    def sliders_from_steps(self, steps: np.ndarray) -> np.ndarray:
        return np.asarray(steps, dtype=float) / self.steps_per_mm

    # ---------------------------------------------------------------- forward
    def fk(
        self,
        sliders: np.ndarray,
        ctx: MotionContext | None = None,
        *,
        tol: float = 1e-11,
        max_iter: int = 30,
    ) -> np.ndarray:
        """Where the effector goes for commanded displacements (N, 3), effects predicted.

        Ideal/slider-only models are closed form; cable stretch depends on the
        tensions at the (unknown) point, solved by a fixed-point iteration that
        found by Newton's method from the unstretched solution.
        """
        s = np.asarray(sliders, dtype=float)
        s_act = s if self.ideal else self.effects.slider_forward(s, ctx or _NO_CONTEXT)
        unstretched = s_act + self.geometry.initial_lengths
        points = fk_from_lengths(unstretched, self.geometry.outlets)
        if not self.effects.has_cable_stage:
            return points
        lost = np.isnan(points[:, 0])
        if lost.any():
            # Unstretched cables can be too short to meet near the outlets' plane:
            # start those rows from cables stretched at the highest allowed tension.
            t_hi = np.full((int(lost.sum()), 3), self.statics.t_max)
            points[lost] = fk_from_lengths(
                self.effects.stretch(unstretched[lost], t_hi), self.geometry.outlets
            )
        for _ in range(max_iter):
            step = self._stretch_newton_step(points, unstretched)
            points = points - step
            if not np.nanmax(np.abs(step), initial=0.0) > tol:
                break
        return points

    def _stretch_residual(self, points: np.ndarray, unstretched: np.ndarray) -> np.ndarray:
        t = tensions(points, self.geometry.outlets, self.statics)
        return cable_lengths(points, self.geometry.outlets) - self.effects.stretch(unstretched, t)

    def _stretch_newton_step(
        self, points: np.ndarray, unstretched: np.ndarray, h: float = 1e-4
    ) -> np.ndarray:
        """One Newton step on |B - A_k| = stretch(u_k, T_k(B)), Jacobian by central differences."""
        r = self._stretch_residual(points, unstretched)
        jac = np.empty(points.shape + (3,))
        for j in range(3):  # three columns, each vectorised over all points
            e = np.zeros(3)
            e[j] = h
            jac[:, :, j] = (
                self._stretch_residual(points + e, unstretched)
                - self._stretch_residual(points - e, unstretched)
            ) / (2 * h)
        return np.linalg.solve(jac, r[..., None])[..., 0]

    def length_residuals(
        self, points: np.ndarray, sliders: np.ndarray, ctx: MotionContext | None = None
    ) -> np.ndarray:
        """|B - A_k| minus the length the model predicts for commanded ``sliders`` (N, 3)."""
        p = np.asarray(points, dtype=float)
        s_act = self.effects.slider_forward(np.asarray(sliders, dtype=float), ctx or _NO_CONTEXT)
        predicted = s_act + self.geometry.initial_lengths
        if self.effects.has_cable_stage:
            predicted = self.effects.stretch(
                predicted, tensions(p, self.geometry.outlets, self.statics)
            )
        return cable_lengths(p, self.geometry.outlets) - predicted

    # -------------------------------------------------------------- workspace
    def check(self, points: np.ndarray, sliders: np.ndarray | None = None) -> WorkspaceReport:
        p = np.asarray(points, dtype=float)
        s = self.ik(p) if sliders is None else sliders
        return check_workspace(p, s, self.limits)

    def home_point(self, home_sliders: np.ndarray) -> np.ndarray:
        """Effector position when every module sits at its endstop."""
        return self.fk(np.asarray(home_sliders, dtype=float).reshape(1, 3))[0]
