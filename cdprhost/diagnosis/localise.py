"""Where does a fitted model disagree with measurement? Findings and a sentence.

Looks at each cable's length residual (measured |B - A_k| minus the length the
model predicts, mm) against time, approach direction, tension, slider position
and height, at a periodic pattern in slider position (a lead-screw error), and at
the position misfit by height band and side of the build volume. Tests are
Bonferroni-corrected over everything looked at; only significant patterns are
reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from cdprhost.calibration.fitting import Observations, whitened_residuals
from cdprhost.diagnosis.stat_tests import pearson
from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import tensions

FEATURES = ("time", "approach direction", "tension", "slider position", "height")


@dataclass(frozen=True)
class Finding:
    kind: str  # one of FEATURES, "periodic", "region"
    cable: int | None  # 1-based; None for whole-pose findings
    statistic: float  # r for correlations, amplitude (mm) for periodic, ratio for region
    p_value: float  # Bonferroni-adjusted
    text: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "cable": self.cable,
            "statistic": self.statistic,
            "p_value": self.p_value,
            "text": self.text,
        }


def _feature_columns(model: MachineModel, obs: Observations) -> dict[str, np.ndarray]:
    n = len(obs)
    t = np.zeros(n) if obs.t_s is None else np.asarray(obs.t_s, float)
    d = np.zeros((n, 3)) if obs.directions is None else np.asarray(obs.directions, float)
    return {
        "time": np.repeat(t[:, None], 3, axis=1),
        "approach direction": d,
        "tension": tensions(obs.measured, model.geometry.outlets, model.statics),
        "slider position": np.asarray(obs.sliders, float),
        "height": np.repeat(obs.measured[:, 2:3], 3, axis=1),
    }


_VERBS = {
    "time": ("grow with time", "fall with time"),
    "approach direction": (
        "follow module {k}'s approach direction",
        "oppose module {k}'s approach direction",
    ),
    "tension": ("grow with tension", "fall with tension"),
    "slider position": ("grow with slider position", "fall with slider position"),
    "height": ("grow with height", "fall with height"),
}


def correlation_findings(
    residuals: np.ndarray, features: dict[str, np.ndarray], n_tests: int, alpha: float
) -> list[Finding]:
    out = []
    for kind, cols in features.items():
        for k in range(3):
            r, p = pearson(cols[:, k], residuals[:, k])
            p_adj = min(1.0, p * n_tests)
            if p_adj < alpha:
                verb = _VERBS[kind][0 if r > 0 else 1].format(k=k + 1)
                out.append(
                    Finding(kind, k + 1, r, p_adj, f"cable {k + 1} residuals {verb} (r = {r:.2f})")
                )
    return out


def periodic_scan(
    s: np.ndarray, y: np.ndarray, min_period: float = 2.0
) -> tuple[float, float, float, float]:
    """Best sinusoid in slider position after removing a line: (period mm, amplitude mm, F, p).

    Scans frequencies 2/span .. 1/min_period at a spacing of 1/(4 span), vectorised;
    p is corrected for the number of independent frequencies scanned."""
    s = np.asarray(s, float)
    y = np.asarray(y, float)
    n = s.size
    span = float(s.max() - s.min())
    if n < 8 or span <= 2 * min_period:
        return float("nan"), 0.0, 0.0, 1.0
    freqs = np.arange(2.0 / span, 1.0 / min_period, 1.0 / (4.0 * span))
    base = np.column_stack([np.ones(n), s - s.mean()])
    qb, _ = np.linalg.qr(base)
    y0 = y - qb @ (qb.T @ y)
    rss0 = float(y0 @ y0)
    ph = 2.0 * np.pi * freqs[:, None] * s[None, :]
    sc = np.stack([np.sin(ph), np.cos(ph)], axis=-1)  # (F, n, 2)
    sc = sc - np.einsum("ni,fij->fnj", qb, np.einsum("ni,fnj->fij", qb, sc))
    gram = np.einsum("fni,fnj->fij", sc, sc)
    rhs = np.einsum("fni,n->fi", sc, y0)
    coef = np.linalg.solve(gram + 1e-12 * np.eye(2), rhs[..., None])[..., 0]
    explained = np.einsum("fi,fi->f", coef, rhs)
    best = int(np.argmax(explained))
    dof = n - 4
    rss1 = max(rss0 - explained[best], 1e-300)
    f_stat = (explained[best] / 2.0) / (rss1 / dof)
    amp = float(np.hypot(*coef[best]))
    n_indep = max(1.0, span * (freqs[-1] - freqs[0]))
    p = float(min(1.0, stats.f.sf(f_stat, 2, dof) * n_indep))
    return float(1.0 / freqs[best]), amp, float(f_stat), p


def periodic_findings(residuals: np.ndarray, sliders: np.ndarray, alpha: float) -> list[Finding]:
    out = []
    for k in range(3):
        period, amp, _, p = periodic_scan(sliders[:, k], residuals[:, k])
        p_adj = min(1.0, 3.0 * p)
        if p_adj < alpha:
            out.append(
                Finding(
                    "periodic",
                    k + 1,
                    amp,
                    p_adj,
                    f"cable {k + 1} residuals repeat with slider position (period ~{period:.1f} mm, amplitude {amp:.2f} mm)",
                )
            )
    return out


def _sides(points: np.ndarray, outlets: np.ndarray) -> np.ndarray:
    """Index of the outlet each point lies towards in the horizontal plane (0, 1, 2)."""
    centre = outlets[:, :2].mean(axis=0)
    a = outlets[:, :2] - centre
    p = points[:, :2] - centre
    cos = (p @ a.T) / (np.linalg.norm(p, axis=1, keepdims=True) * np.linalg.norm(a, axis=1) + 1e-12)
    return np.asarray(np.argmax(cos, axis=1))


def region_finding(
    whitened: np.ndarray, points: np.ndarray, outlets: np.ndarray, alpha: float
) -> list[Finding]:
    """The height band x side cell where the misfit is largest, if it stands out."""
    sq = np.sum(whitened * whitened, axis=1)
    n = sq.size
    if n < 9:
        return []
    z = points[:, 2]
    edges = np.quantile(z, [1 / 3, 2 / 3])
    band = np.searchsorted(edges, z)
    side = _sides(points, outlets)
    total = float(sq.sum())
    best = None
    n_cells = 0
    for b in range(3):
        for s in range(3):
            m = (band == b) & (side == s)
            if m.sum() < 3:
                continue
            n_cells += 1
            # share of the misfit in this cell vs its share of poses: a one-sided
            # F-type comparison of the cell's mean chi2 against the rest
            rest = ~m
            f = (sq[m].mean()) / max(sq[rest].mean(), 1e-300)
            p = float(stats.f.sf(f, 3 * m.sum(), 3 * rest.sum()))
            if best is None or p < best[0]:
                best = (p, b, s, f, float(sq[m].sum()) / total)
    if best is None:
        return []
    p, b, s, f, share = best
    p_adj = min(1.0, p * n_cells)
    if p_adj >= alpha:
        return []
    words = ("low", "middle", "high")[b]
    return [
        Finding(
            "region",
            None,
            f,
            p_adj,
            f"errors largest at {words} z near the A_{s + 1} side ({share:.0%} of the misfit, mean {f:.1f}x the rest)",
        )
    ]


def localise(model: MachineModel, obs: Observations, alpha: float = 0.01) -> list[Finding]:
    """All significant patterns in ``model``'s disagreement with ``obs``, most significant first."""
    residuals = model.length_residuals(obs.measured, obs.sliders, obs.context)
    residuals = residuals - residuals.mean(axis=0)
    features = _feature_columns(model, obs)
    if obs.t_s is None:
        features.pop("time")
    if obs.directions is None or not np.any(obs.directions):
        features.pop("approach direction")
    n_tests = 3 * len(features)
    found = correlation_findings(residuals, features, n_tests, alpha)
    found += periodic_findings(residuals, np.asarray(obs.sliders, float), alpha)
    found += region_finding(
        whitened_residuals(model, obs), obs.measured, model.geometry.outlets, alpha
    )
    return sorted(found, key=lambda f: (f.p_value, -abs(f.statistic)))


def describe(
    findings: list[Finding],
    chi2: float,
    dof: int,
    gof_p: float,
    *,
    gof_alpha: float = 1e-3,
    explained: bool = False,
    limit: int = 3,
) -> str:
    """One sentence for the report's ``where``.

    ``explained``: an effect was named (or candidates are ambiguous), so a
    disagreement exists even if the chi-square test alone did not flag it."""
    fit = f"chi2 = {chi2:.1f} on {dof} dof"
    if not findings:
        if gof_p < gof_alpha:
            return (
                f"disagreement beyond the noise floor ({fit}) spread over poses and cables, with no pattern "
                "in time, approach direction, tension, slider position, height or region"
            )
        if explained:
            return f"a small disagreement ({fit}, p = {gof_p:.2g}) with no single pattern"
        return f"no disagreement beyond the noise floor ({fit})"
    if gof_p >= gof_alpha and not explained:
        return f"no disagreement beyond the noise floor ({fit})"
    picked: list[Finding] = []
    seen: set[tuple[str, int | None]] = set()
    for f in findings:  # at most one statement per (kind, cable), strongest first
        key = (f.kind, f.cable)
        if key not in seen:
            picked.append(f)
            seen.add(key)
        if len(picked) == limit:
            break
    return "; ".join(f.text for f in picked)
