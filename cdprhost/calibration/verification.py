"""Verify-then-refine: do the check poses agree with what the fit poses predict?

The geometry identified from the fit poses alone predicts where the effector is at each
check pose. Its prediction error there is the sum of two independent parts: the check
take's own noise (sigma_i^2 I, from the take's standard error) and the parameter
uncertainty carried to that pose, J0_i Sigma J0_i^T (Sigma from the fit poses' noise, the
same covariance the trust gate uses). Stacked over the M check poses the residual r (3M)
has covariance C = diag(sigma_i^2 I3) + J0 Sigma J0^T (the parameter part correlates the
poses), so for a sound session and a complete model r^T C^-1 r follows chi-square with 3M
degrees of freedom.

The session is called inconsistent when that joint test has p < alpha (default 1 %: the
false-alarm rate of a sound session). Each pose's own statistic (its 3x3 block, 3 dof) then
names the culprit(s): the poses whose own p is below alpha/M (Bonferroni), else the largest.
One pose carrying most of the chi-square points to a bad take (a bump, a wrong marker); a
disagreement spread over the check poses to an effect the model lacks. (A per-pose test in
the verdict would add power against one bad take, but it rides on the tails of each take's
standard error, which real takes fatten; the joint test averages them.) When consistent,
the check poses carry information like any other pose and the geometry is refitted on all.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from cdprhost.jsonsafe import json_safe

DEFAULT_ALPHA = 0.01
CONSISTENT, INCONSISTENT, UNTESTED = "consistent", "inconsistent", "untested"


@dataclass(frozen=True)
class CheckPose:
    """One check pose: the fit-only prediction minus the measurement, and what was expected."""

    pose: int  # poses.csv number
    residual: np.ndarray  # (3,) predicted - measured, mm
    noise_sigma_mm: float  # the take's own noise, per coordinate
    predicted_sigma_mm: float  # RMS 3D prediction error expected: sqrt(trace C_i)
    chi2: float  # r_i^T C_i^-1 r_i, 3 dof
    p_value: float

    @property
    def residual_mm(self) -> float:
        return float(np.linalg.norm(self.residual))

    def to_json(self) -> dict[str, Any]:
        return {
            "pose": self.pose,
            "residual_mm": self.residual_mm,
            "residual": self.residual.tolist(),
            "predicted_sigma_mm": self.predicted_sigma_mm,
            "noise_sigma_mm": self.noise_sigma_mm,
            "chi2": self.chi2,
            "dof": 3,
            "p_value": self.p_value,
        }


@dataclass(frozen=True)
class Verification:
    """The check poses against the fit-only prediction, and what was done with them."""

    checks: tuple[CheckPose, ...]
    chi2: float
    dof: int
    p_value: float
    alpha: float
    verdict: str  # consistent | inconsistent | untested
    suspects: tuple[int, ...]  # poses.csv numbers of the check poses that disagree most
    fit_only_rms_mm: float = float("nan")  # predicted workspace error of the fit-only geometry
    fit_only_max_mm: float = float("nan")
    refined: bool = False  # the geometry was refitted on fit + check poses
    refined_rms_mm: float = float("nan")
    refined_max_mm: float = float("nan")
    rows: tuple[int, ...] = ()  # the check poses' rows in the observations

    @property
    def errors_mm(self) -> np.ndarray:
        """Each check pose's prediction error by the fit-only geometry, (M,) mm."""
        return np.array([c.residual_mm for c in self.checks])

    @property
    def consistent(self) -> bool:
        return self.verdict == CONSISTENT

    def problem(self) -> str | None:
        """The refusal when the check poses disagree (None otherwise)."""
        if self.verdict != INCONSISTENT:
            return None
        worst = ", ".join(
            f"pose {c.pose} off by {c.residual_mm:.3f} mm where {c.predicted_sigma_mm:.3f} mm "
            f"was expected (p {c.p_value:.2g})"
            for c in self.checks
            if c.pose in self.suspects
        )
        one = len(self.suspects) == 1 and max(c.chi2 for c in self.checks) > 0.6 * self.chi2
        cause = (
            "likely a bad take of that pose (bumped, moved, a wrong marker: record it again), "
            "else an effect the model lacks (run `cdprhost diagnose` on a session of 8 poses "
            "or more, e.g. the wizard's `--poses 12`)"
            if one
            else "likely an effect the model lacks (cable stretch, drive scale, backlash, drift: "
            "run `cdprhost diagnose` on a session of 8 poses or more, e.g. the wizard's "
            "`--poses 12`), else bad takes, or pose noise the takes "
            "cannot show (a static positioning error: declare it with --noise-floor)"
        )
        return (
            f"the check poses disagree with the fit poses' prediction (chi2 {self.chi2:.1f} on "
            f"{self.dof} dof, p {self.p_value:.2g}; {worst}): {cause}"
        )

    def text(self) -> str:
        head = (
            f"verification of the fit poses on {len(self.checks)} check pose(s): {self.verdict.upper()} "
            f"(chi2 {self.chi2:.2f} on {self.dof} dof, p {self.p_value:.3g}; false-alarm rate "
            f"{self.alpha:g})"
        )
        rows = [
            f"  check pose {c.pose}: residual {c.residual_mm:.4f} mm, predicted sigma "
            f"{c.predicted_sigma_mm:.4f} mm, chi2 {c.chi2:.2f}/3, p {c.p_value:.3g}"
            + ("  <- disagrees" if c.pose in self.suspects else "")
            for c in self.checks
        ]
        ws = f"predicted workspace error, fit poses only: RMS {self.fit_only_rms_mm:.3f} mm, max {self.fit_only_max_mm:.3f} mm"
        if self.refined:
            ws += (
                f"; refined on fit + check poses: RMS {self.refined_rms_mm:.3f} mm, "
                f"max {self.refined_max_mm:.3f} mm"
            )
        return "\n".join([head, *rows, ws])

    def to_json(self) -> dict[str, Any]:
        return dict(
            json_safe(
                {
                    "verdict": self.verdict,
                    "chi2": self.chi2,
                    "dof": self.dof,
                    "p_value": self.p_value,
                    "alpha": self.alpha,
                    "suspects": list(self.suspects),
                    "checks": [c.to_json() for c in self.checks],
                    "refined": self.refined,
                    "workspace_fit_only": {
                        "rms_mm": self.fit_only_rms_mm,
                        "max_mm": self.fit_only_max_mm,
                    },
                    "workspace_refined": {
                        "rms_mm": self.refined_rms_mm,
                        "max_mm": self.refined_max_mm,
                    }
                    if self.refined
                    else None,
                }
            )
        )


def verify_checks(
    residuals: np.ndarray,
    noise_sigma_mm: np.ndarray,
    jacobians: np.ndarray,
    covariance: np.ndarray,
    pose_numbers: np.ndarray,
    alpha: float = DEFAULT_ALPHA,
) -> Verification:
    """Test the check poses' residuals (M, 3) (fit-only prediction - measured) against
    their predicted covariance: noise ``noise_sigma_mm`` (M,) plus ``jacobians`` (M, 3, 12)
    carrying the fit's parameter ``covariance`` (12, 12)."""
    r = np.asarray(residuals, dtype=float).reshape(-1, 3)
    m = r.shape[0]
    sig = np.broadcast_to(np.asarray(noise_sigma_mm, dtype=float), (m,))
    numbers = tuple(int(n) for n in np.asarray(pose_numbers).reshape(-1))
    if m == 0 or not (np.all(np.isfinite(covariance)) and np.all(np.isfinite(r))):
        return Verification((), float("nan"), 0, float("nan"), alpha, UNTESTED, ())
    j = np.asarray(jacobians, dtype=float).reshape(m * 3, -1)
    cov = j @ covariance @ j.T + np.diag(np.repeat(sig**2, 3))
    flat = r.reshape(-1)
    chi2 = float(flat @ np.linalg.solve(cov, flat))
    dof = 3 * m
    p = float(stats.chi2.sf(chi2, dof))
    blocks = np.stack([cov[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(m)])
    chi2_i = np.einsum("ni,ni->n", r, np.linalg.solve(blocks, r[..., None])[..., 0])
    p_i = stats.chi2.sf(chi2_i, 3)
    checks = tuple(
        CheckPose(
            numbers[i],
            r[i],
            float(sig[i]),
            float(np.sqrt(np.trace(blocks[i]))),
            float(chi2_i[i]),
            float(p_i[i]),
        )
        for i in range(m)
    )
    bad = bool(p < alpha)
    single = np.flatnonzero(p_i < alpha / m)
    if not bad:
        suspects: tuple[int, ...] = ()
    elif single.size:
        suspects = tuple(numbers[i] for i in single)
    else:
        suspects = (numbers[int(np.argmax(chi2_i))],)
    return Verification(checks, chi2, dof, p, alpha, INCONSISTENT if bad else CONSISTENT, suspects)
