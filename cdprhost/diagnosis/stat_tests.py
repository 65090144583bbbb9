"""Statistical tests used to decide whether a model disagrees with measurement.

All take chi-square values of *whitened* residuals (misfit / sigma), so with the
right model and the right sigma ``chi2 ~ chi2(dof)``.

- :func:`goodness_of_fit_p`: does the misfit exceed the noise floor?
- :func:`nested_f_test`: does adding ``extra`` parameters reduce chi2 more than
  noise would? Uses the full model's own variance estimate, so it stays valid if
  the declared sigma is somewhat off.
- :func:`likelihood_ratio_p`: the same question with sigma taken as known.
- :func:`bic`: Bayesian information criterion for Gaussian errors of known sigma.
- :func:`holm`: Holm-Bonferroni adjusted p-values (family-wise error control).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats


def goodness_of_fit_p(chi2: float, dof: int) -> float:
    """P(chi2(dof) >= chi2): small means the misfit exceeds the noise."""
    if dof <= 0:
        return float("nan")
    return float(stats.chi2.sf(chi2, dof))


def nested_f_test(
    chi2_small: float, chi2_big: float, extra: int, dof_big: int
) -> tuple[float, float]:
    """F statistic and p-value of a nested comparison (big model has ``extra`` more parameters)."""
    if extra <= 0 or dof_big <= 0 or chi2_big <= 0:
        return float("nan"), float("nan")
    f = max(chi2_small - chi2_big, 0.0) / extra / (chi2_big / dof_big)
    return float(f), float(stats.f.sf(f, extra, dof_big))


def likelihood_ratio_p(chi2_small: float, chi2_big: float, extra: int) -> float:
    """p-value of chi2_small - chi2_big against chi2(extra) (known sigma)."""
    if extra <= 0:
        return float("nan")
    return float(stats.chi2.sf(max(chi2_small - chi2_big, 0.0), extra))


def bic(chi2: float, n_params: int, n_obs: int) -> float:
    """-2 log-likelihood (up to a constant) + p ln n, for Gaussian errors of known sigma."""
    return float(chi2 + n_params * math.log(max(n_obs, 1)))


def holm(p_values: np.ndarray | list[float]) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values (same order as given; NaN stays NaN)."""
    p = np.asarray(p_values, dtype=float)
    out = np.full_like(p, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    m = ok.size
    if m == 0:
        return out
    order = ok[np.argsort(p[ok])]
    scaled = p[order] * (m - np.arange(m))
    out[order] = np.minimum(np.maximum.accumulate(scaled), 1.0)
    return out


def pearson(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Pearson r and its two-sided p-value; (0, 1) when either input is constant."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = x.size
    xc, yc = x - x.mean(), y - y.mean()
    den = math.sqrt(float(xc @ xc) * float(yc @ yc))
    if n < 4 or den <= 1e-300:
        return 0.0, 1.0
    r = float(np.clip((xc @ yc) / den, -1.0, 1.0))
    if abs(r) >= 1.0:
        return r, 0.0
    t = r * math.sqrt((n - 2) / (1.0 - r * r))
    return r, float(2.0 * stats.t.sf(abs(t), n - 2))
