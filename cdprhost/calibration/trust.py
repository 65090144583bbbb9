"""May an identified geometry be trusted? Predicted workspace error and the gate.

The parameter covariance Sigma (12 x 12, mm^2) of an identification is carried to the
build volume: a calibrated model commanding a target x puts the effector off by
dB = J0(x) dq, so the predicted position error there is sigma(x) = sqrt(tr(J0 Sigma J0^T)).
On a grid over the build volume (:func:`~cdprhost.kinematics.grid.workspace_grid`) the
RMS and the largest sigma(x) are the predicted workspace error.

Sigma comes from the pose noise (the takes' standard errors), so it can only be believed
when the data can contradict that noise: residual degrees of freedom of the fit, or check
poses that were predicted, not fitted. Their pooled chi-square per degree of freedom scales
Sigma up (never down). With neither, the noise cannot be estimated and the gate refuses.

The predicted RMS is that of the expected squared error; one calibration's error is one
draw. Its mean squared workspace error is a sum of independent normal directions squared
(the eigenvalues of the workspace-weighted covariance, :func:`error_spectrum`), and when
one direction carries most of it (a camera session's frame shifted along the line of
sight: about 1.3 to 3 effective degrees of freedom) a single calibration's RMS scatters by
a factor of two either way around the prediction. The report states that spread: the
effective degrees of freedom and the range the RMS of one calibration falls in 8 times
out of 10 (:func:`rms_spread`, from draws of those directions). The covariance itself is
checked against the scatter of the estimates over many camera sessions
(``bench/trust_scatter.py``): the error whitened by it has unit variance and the predicted
RMS is the expected one, so a session far from it is such a draw, not a bias.

The gate refuses (unless forced) when the predicted error exceeds ``max_workspace_mm`` or
the noise cannot be estimated; it warns above ``warn_workspace_mm``. The parameter
combinations behind a large prediction are named: the generalised eigenvectors of the
workspace metric W = mean J0^T J0 against the information Sigma^-1, each carrying its
share of the mean squared workspace error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg

from cdprhost.calibration.fitting import GEOMETRY_NAMES
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.jacobian import identification_jacobian


@dataclass(frozen=True)
class TrustLimits:
    max_workspace_mm: float = 1.0
    warn_workspace_mm: float = 0.3


DEFAULT_TRUST = TrustLimits()


@dataclass(frozen=True)
class WeakCombination:
    """A parameter direction (unit vector over the 12) and the RMS workspace error it carries."""

    vector: np.ndarray
    workspace_mm: float

    def text(self, top: int = 4) -> str:
        order = np.argsort(-np.abs(self.vector))[:top]
        terms = " ".join(
            f"{self.vector[i]:+.2f}*{GEOMETRY_NAMES[i]}"
            for i in order
            if abs(self.vector[i]) > 0.05
        )
        size = "unbounded" if not np.isfinite(self.workspace_mm) else f"{self.workspace_mm:.3g} mm"
        return f"{terms} ({size} of workspace error)"


@dataclass(frozen=True)
class TrustReport:
    predicted_rms_mm: float
    predicted_max_mm: float
    variance_factor: float  # chi2/dof of fit residuals and check poses pooled, >= 1 applied
    noise_dof: int  # residual dof + 3 x check poses
    weak: tuple[WeakCombination, ...]
    refusals: tuple[str, ...]
    warnings: tuple[str, ...] = field(default=())
    # the spread of one calibration's workspace RMS around the prediction (module doc)
    effective_dof: float = float("nan")
    likely_rms_mm: tuple[float, float] = (float("nan"), float("nan"))
    spectrum_mm2: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def quantile_of(self, rms_mm: float) -> float:
        """Where an observed workspace RMS falls in the predicted distribution (0..1)."""
        return rms_quantile(self.spectrum_mm2, rms_mm)

    @property
    def trusted(self) -> bool:
        return not self.refusals

    def to_json(self) -> dict[str, Any]:
        return {
            "predicted_workspace_rms_mm": self.predicted_rms_mm,
            "predicted_workspace_max_mm": self.predicted_max_mm,
            "variance_factor": self.variance_factor,
            "noise_dof": self.noise_dof,
            "weak_combinations": [w.text() for w in self.weak],
            "refusals": list(self.refusals),
            "warnings": list(self.warnings),
            "effective_dof": self.effective_dof,
            "likely_workspace_rms_mm": list(self.likely_rms_mm),
        }

    def spread_text(self) -> str:
        """One line on how far one calibration's RMS may fall from the prediction."""
        lo, hi = self.likely_rms_mm
        if not (np.isfinite(lo) and np.isfinite(hi)):
            return ""
        return (
            f"one calibration's workspace RMS falls between {lo:.3g} and {hi:.3g} mm 8 times "
            f"out of 10 (its error has {self.effective_dof:.2g} effective degrees of freedom)"
        )


def workspace_sigma(
    geometry: CableGeometry, covariance: np.ndarray, grid: np.ndarray
) -> np.ndarray:
    """Predicted position error sqrt(tr(J0 Sigma J0^T)) at every grid point, (N,) mm."""
    j0 = identification_jacobian(grid, geometry).reshape(-1, 3, 12)
    var = np.einsum("nip,pq,niq->n", j0, covariance, j0)
    return np.asarray(np.sqrt(np.clip(var, 0.0, None)))


def frame_variance(frame_covariance: np.ndarray | None, grid: np.ndarray) -> np.ndarray | float:
    """E|w x x + t|^2 at every grid point for a rigid error (w, t) of covariance (6, 6)."""
    if frame_covariance is None:
        return 0.0
    x = np.asarray(grid, float)
    jac = np.zeros((x.shape[0], 3, 6))
    jac[:, 0, 1], jac[:, 0, 2] = x[:, 2], -x[:, 1]  # -[x]x w = w x x
    jac[:, 1, 0], jac[:, 1, 2] = -x[:, 2], x[:, 0]
    jac[:, 2, 0], jac[:, 2, 1] = x[:, 1], -x[:, 0]
    jac[:, :, 3:] = np.eye(3)
    return np.asarray(np.einsum("nip,pq,niq->n", jac, np.asarray(frame_covariance, float), jac))


def _psd_root(cov: np.ndarray) -> np.ndarray:
    """L with L L^T = cov (negative eigenvalues of rounding clipped)."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return np.asarray(v * np.sqrt(np.clip(w, 0.0, None)))


def frame_metric(grid: np.ndarray) -> np.ndarray:
    """Mean over the grid of the (3, 6) Jacobian of w x x + t, squared: (6, 6)."""
    x = np.asarray(grid, float)
    jac = np.zeros((x.shape[0], 3, 6))
    jac[:, 0, 1], jac[:, 0, 2] = x[:, 2], -x[:, 1]
    jac[:, 1, 0], jac[:, 1, 2] = -x[:, 2], x[:, 0]
    jac[:, 2, 0], jac[:, 2, 1] = x[:, 1], -x[:, 0]
    jac[:, :, 3:] = np.eye(3)
    return np.asarray(np.einsum("nip,niq->pq", jac, jac) / x.shape[0])


def error_spectrum(
    geometry: CableGeometry,
    covariance: np.ndarray,
    grid: np.ndarray,
    common_covariance: np.ndarray | None = None,
    frame_covariance: np.ndarray | None = None,
) -> np.ndarray:
    """Variances of the independent normal directions whose squares add up to one
    calibration's mean squared workspace error: the eigenvalues of L^T W L for the
    parameters (``covariance`` = L L^T, W the workspace metric), of the common vector's
    covariance, and of the frame error's against its metric. They sum to the predicted
    RMS squared."""
    parts = []
    lp = _psd_root(np.asarray(covariance, float))
    parts.append(np.linalg.eigvalsh(lp.T @ workspace_metric(geometry, grid) @ lp))
    if common_covariance is not None:
        parts.append(np.linalg.eigvalsh(np.asarray(common_covariance, float)))
    if frame_covariance is not None:
        lf = _psd_root(np.asarray(frame_covariance, float))
        parts.append(np.linalg.eigvalsh(lf.T @ frame_metric(grid) @ lf))
    lam = np.clip(np.concatenate(parts), 0.0, None)
    return np.asarray(lam[lam > 0])


#: Draws of the error's directions behind the spread's quantiles (fixed, so a report is
#: the same every time; quantiles to about 1 %).
SPREAD_DRAWS = 20000


def _rms_draws(spectrum: np.ndarray) -> np.ndarray:
    """One calibration's RMS, drawn SPREAD_DRAWS times: sqrt(sum lam z^2), sorted."""
    lam = np.asarray(spectrum, float)
    z = np.random.default_rng(0).standard_normal((SPREAD_DRAWS, lam.size))
    return np.sort(np.sqrt((z**2) @ lam))


def _finite_spectrum(spectrum: np.ndarray) -> bool:
    lam = np.asarray(spectrum, float)
    return bool(lam.size and np.all(np.isfinite(lam)) and lam.sum() > 0)


def rms_spread(spectrum: np.ndarray, probs: tuple[float, float] = (0.1, 0.9)) -> tuple[float, ...]:
    """The RMS one calibration stays below with probabilities ``probs`` (quantiles, mm)."""
    if not _finite_spectrum(spectrum):
        return tuple(float("nan") for _ in probs)
    return tuple(float(v) for v in np.quantile(_rms_draws(spectrum), probs))


def rms_quantile(spectrum: np.ndarray, rms_mm: float) -> float:
    """Where an observed workspace RMS falls in the predicted distribution (0..1): over
    many sessions these are uniform when the prediction is right."""
    if not _finite_spectrum(spectrum):
        return float("nan")
    draws = _rms_draws(spectrum)
    return float(np.searchsorted(draws, rms_mm) / draws.size)


def effective_dof(spectrum: np.ndarray) -> float:
    """(sum lam)^2 / sum lam^2: how many equal directions the error behaves like."""
    if not _finite_spectrum(spectrum):
        return float("nan")
    lam = np.asarray(spectrum, float)
    return float(lam.sum() ** 2 / np.sum(lam**2))


def workspace_metric(geometry: CableGeometry, grid: np.ndarray) -> np.ndarray:
    """W = mean over the grid of J0^T J0, (12, 12): dq^T W dq is the mean squared error."""
    j0 = identification_jacobian(grid, geometry).reshape(-1, 3, 12)
    return np.asarray(np.einsum("nip,niq->pq", j0, j0) / j0.shape[0])


def weak_combinations(
    information: np.ndarray, metric: np.ndarray, threshold_mm: float, top: int = 3
) -> tuple[WeakCombination, ...]:
    """Parameter combinations whose uncertainty alone gives more than ``threshold_mm`` RMS
    workspace error (largest first, at most ``top``)."""
    if not (np.all(np.isfinite(information)) and np.all(np.isfinite(metric))):
        return ()
    scale = np.sqrt(np.maximum(np.diag(metric), 1e-300))
    w = metric / np.outer(scale, scale) + 1e-12 * np.eye(metric.shape[0])
    info = information / np.outer(scale, scale)
    ridge = 1e-12 * max(float(np.trace(info)) / info.shape[0], 1e-300)
    try:
        mu, vec = linalg.eigh(info + ridge * np.eye(info.shape[0]), w)  # info v = mu W v
    except linalg.LinAlgError:
        return ()
    contribution = np.where(mu > ridge * 10, 1.0 / np.maximum(mu, 1e-300), np.inf)
    out = []
    for k in np.argsort(-contribution)[:top]:
        mm = float(np.sqrt(contribution[k]))
        if mm <= threshold_mm:
            break
        v = vec[:, k] / scale
        out.append(WeakCombination(v / np.linalg.norm(v), mm))
    return tuple(out)


def variance_factor(
    chi2_fit: float,
    dof_fit: int,
    check_residuals: np.ndarray,
    check_cov: np.ndarray,
) -> tuple[float, int]:
    """Pooled chi-square per degree of freedom of the fit residuals and the check poses'
    prediction errors (each whitened by its predicted covariance, (M, 3, 3)), and the dof."""
    chi2 = chi2_fit if dof_fit > 0 else 0.0
    dof = max(dof_fit, 0)
    if check_residuals.size:
        r = check_residuals.reshape(-1, 3)
        sol = np.linalg.solve(check_cov, r[..., None])[..., 0]
        chi2 += float(np.sum(r * sol))
        dof += 3 * r.shape[0]
    return (chi2 / dof if dof > 0 else float("nan")), dof


def trust_report(
    geometry: CableGeometry,
    covariance: np.ndarray,
    information: np.ndarray,
    grid: np.ndarray,
    factor: float,
    noise_dof: int,
    limits: TrustLimits = DEFAULT_TRUST,
    *,
    parameter_covariance: np.ndarray | None = None,
    common_covariance: np.ndarray | None = None,
    frame_covariance: np.ndarray | None = None,
) -> TrustReport:
    """The gate on an identification whose (unscaled) covariance is ``covariance``.

    ``parameter_covariance`` (12, 12): what errors shared by every pose (a camera's
    intrinsics and pose) add to the parameters, which the poses' noise cannot show;
    ``common_covariance`` (3, 3): one vector added to every measured point (a camera's
    effector-board orientation times its offset), which identification cannot see but a
    print does; ``frame_covariance`` (6, 6): a rigid error of the measuring frame (rotation
    vector about the base origin, translation), which moves the point x by w x x + t: all
    are added to the prediction."""
    scale = max(factor, 1.0) if np.isfinite(factor) else 1.0
    cov = covariance * scale
    if parameter_covariance is not None:
        cov = cov + np.asarray(parameter_covariance, float)
    common = 0.0 if common_covariance is None else float(np.trace(common_covariance))
    if np.all(np.isfinite(cov)):
        sigma = np.sqrt(
            workspace_sigma(geometry, cov, grid) ** 2
            + common
            + frame_variance(frame_covariance, grid)
        )
        rms, worst = float(np.sqrt(np.mean(sigma**2))), float(np.max(sigma))
        spectrum = error_spectrum(geometry, cov, grid, common_covariance, frame_covariance)
        dof = effective_dof(spectrum)
        lo, hi = rms_spread(spectrum)
    else:
        rms = worst = float("inf")
        dof, lo, hi = float("nan"), float("inf"), float("inf")
        spectrum = np.zeros(0)
    weak = weak_combinations(
        information / scale, workspace_metric(geometry, grid), limits.warn_workspace_mm
    )
    refusals, warnings = [], []
    if noise_dof <= 0:
        refusals.append(
            "the noise cannot be estimated: no residual degrees of freedom (4 fit poses "
            "determine the 12 parameters exactly; each further pose adds 3) and no check poses "
            "to test the prediction against"
        )
    if not worst <= limits.max_workspace_mm:
        shown = "unbounded" if not np.isfinite(worst) else f"{worst:.3g} mm"
        refusals.append(
            f"predicted workspace error up to {shown} (RMS {rms:.3g} mm) exceeds {limits.max_workspace_mm:g} mm"
        )
    elif worst > limits.warn_workspace_mm:
        warnings.append(
            f"predicted workspace error up to {worst:.3g} mm (RMS {rms:.3g} mm), above {limits.warn_workspace_mm:g} mm: "
            "more or better-spread poses would help"
        )
    if weak and (refusals or warnings):
        text = "; ".join(w.text() for w in weak)
        (refusals if refusals else warnings).append(
            f"weakly observed parameter combination(s): {text}"
        )
    if np.isfinite(factor) and factor > 1.0:
        warnings.append(
            f"residuals are {np.sqrt(factor):.2g}x the take noise (chi2/dof {factor:.3g} over {noise_dof} dof): "
            "uncertainties scaled up accordingly"
        )
    return TrustReport(
        rms,
        worst,
        factor,
        noise_dof,
        weak,
        tuple(refusals),
        tuple(warnings),
        dof,
        (lo, hi),
        spectrum,
    )
