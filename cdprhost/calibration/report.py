"""Plain-text tables of pose plans and identification results (for the CLI and TUI)."""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.identification import Identification
from cdprhost.calibration.planning import INDEX_NAMES, PosePlan


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [
        max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)
    ]

    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) for c, w in zip(cells, widths))

    return "\n".join([line(header), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def _mm(v: float | None, digits: int = 4) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def plan_text(plan: PosePlan) -> str:
    rows = [
        [str(i + 1), role, *(f"{v:.2f}" for v in p), *(f"{int(d):+d}" for d in dirs)]
        for i, (p, role, dirs) in enumerate(zip(plan.poses, plan.roles, plan.directions))
    ]
    poses = _table(["pose", "role", "x", "y", "z", "dir1", "dir2", "dir3"], rows)
    idx = _table(
        ["index", "planned", "Table 1", "ratio"],
        [
            [
                n,
                f"{plan.indices[n]:.4g}",
                f"{plan.table1_indices[n]:.4g}",
                f"{plan.indices[n] / plan.table1_indices[n]:.3g}x"
                if plan.table1_indices[n] > 0
                else "-",
            ]
            for n in INDEX_NAMES
        ],
    )
    n_fit = sum(r == "fit" for r in plan.roles)
    return (
        f"{n_fit} fit + {len(plan.roles) - n_fit} check poses, criterion {plan.criterion}, "
        f"{plan.n_candidates} feasible candidates, travel {plan.travel_mm:.0f} mm "
        "(each pose approached straight down from above)\n"
        f"{poses}\n\nobservability (column-scaled identification Jacobian)\n{idx}"
    )


def summary_text(r: Identification) -> str:
    """The before/after table."""
    fit, chk = r.fit_mask, r.check_rows
    rows = [
        ["fit poses RMS", _mm(r.rms_before_mm), _mm(r.rms_after_mm)],
        [
            "fit poses max",
            _mm(r.errors_before[fit].max() if fit.any() else None),
            _mm(r.errors_after[fit].max() if fit.any() else None),
        ],
    ]
    if chk.size:
        note = " (predicted by the fit poses)" if r.verification and r.verification.refined else ""
        rows += [
            ["check poses RMS" + note, _mm(r.check_rms_before_mm), _mm(r.check_rms_after_mm)],
            [
                "check poses max" + note,
                _mm(r.errors_before[chk].max()),
                _mm(r.check_errors_after.max()),
            ],
        ]
    return _table(["position error (mm)", "before", "after"], rows)


def parameters_text(r: Identification) -> str:
    rows = []
    for i, name in enumerate(r.names):
        nom, val, se = r.nominal.q[i], r.geometry.q[i], r.stderr[i]
        lo, hi = r.ci95[i]
        rows.append(
            [
                name,
                f"{nom:.4f}",
                f"{val:.4f}",
                f"{val - nom:+.4f}",
                _mm(se),
                f"[{_mm(lo, 3)}, {_mm(hi, 3)}]",
            ]
        )
    return _table(["parameter", "nominal", "identified", "change", "stderr", "95% interval"], rows)


def poses_text(r: Identification) -> str:
    roles = list(r.roles)
    if r.verification is not None and r.verification.refined:
        for i in r.check_rows:
            roles[i] = "check+fit"  # verified as a check pose, then used in the refit
    rows = [
        [str(i + 1), role, _mm(b), _mm(a), *(_mm(v, 4) for v in res), _mm(s)]
        for i, (role, b, a, res, s) in enumerate(
            zip(roles, r.errors_before, r.errors_after, r.residuals_after, r.sigma_mm)
        )
    ]
    return _table(["pose", "role", "before", "after", "dx", "dy", "dz", "sigma"], rows)


def trust_text(r: Identification) -> str:
    """The trust gate's verdict: predicted workspace error, refusals, warnings."""
    lines = [
        (
            "predicted workspace error (from the parameter uncertainty): "
            f"RMS {_mm(r.predicted_workspace_rms_mm, 3)} mm, max {_mm(r.predicted_workspace_max_mm, 3)} mm"
        )
    ]
    if r.trust is not None and r.trust.spread_text():
        lines.append(r.trust.spread_text())
    if r.noise is not None:
        lines.append(
            f"pose noise: {r.noise.typical_mm:.3g} mm RMS per coordinate ({r.noise.source})"
        )
    lines.append("TRUSTED" if r.ok else "NOT TRUSTED")
    lines += [f"  refused: {p}" for p in r.problems()]
    lines += [f"  warning: {w}" for w in r.warnings()]
    return "\n".join(lines)


def identification_text(r: Identification) -> str:
    parts = [
        (
            f"poses used {r.poses_used}, iterations {r.iterations}, "
            f"converged {'yes' if r.converged else 'NO'}, chi2/dof {r.chi2:.3g}/{r.dof}"
        ),
        summary_text(r),
        parameters_text(r),
        "per pose (mm; residual = predicted - measured)",
        poses_text(r),
        "scaled singular values: " + " ".join(f"{v:.3g}" for v in r.singular_values),
    ]
    if r.correlations:
        parts.append(
            "correlations above 0.95: "
            + ", ".join(f"{a}~{b} {c:+.3f}" for a, b, c in r.correlations)
        )
    if r.unidentifiable:
        parts.append("UNIDENTIFIABLE combinations: " + "; ".join(r.unidentifiable))
    if r.verification is not None:
        parts.append(r.verification.text())
    parts.append(trust_text(r))
    if r.rejected:
        parts.append("rejected takes:\n" + "\n".join(f"  {t}" for t in r.rejected))
    return "\n\n".join(parts)
