"""A diagnosis as a JSON-ready dict (spec/cli-contract.md fields and more) and as
terminal text with tables. Also used by the TUI (``summary_lines``, ``candidate_rows``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cdprhost.diagnosis.workflow import Candidate, Diagnosis
from cdprhost.jsonsafe import json_safe

ADVICE = {
    "drift": "drift is not compensated while printing (time is unknown there): re-home the modules before each print",
    "backlash": "backlash is compensated along the printed path; check the belt/coupling if the lash is large",
    "drive_scale": "drive scale is compensated; check steps_per_mm or the screw lead of the modules named",
    "cable_elasticity": "cable stretch is compensated from the computed tensions",
}


def candidate_dict(c: Candidate) -> dict[str, Any]:
    return {
        "name": c.name,
        "round": c.round,
        "p_value": c.p_value,
        "p_holm": c.p_holm,
        "f_stat": c.f_stat,
        "delta_bic": c.delta_bic,
        "heldout_rms_mm": c.heldout_rms_mm,
        "unabsorbed": c.unabsorbed,
        "status": c.status,
    }


def advice(d: Diagnosis) -> list[str]:
    out = [ADVICE[n] for n in d.final.effects if n in ADVICE and n not in d.base.effects]
    if d.verdict == "unexplained":
        out.append(
            "the model lacks some physics: look where the disagreement is (see 'where'); "
            "no catalogue effect explains it"
        )
    if d.verdict == "ambiguous":
        out.append(
            f"{' and '.join(d.ambiguous_between)} explain the same disagreement on these poses: "
            "measure more poses that separate them (other heights, visiting orders and directions)"
        )
    return out


def to_json(
    d: Diagnosis, *, session: str = "", rejected: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """Every field of spec/cli-contract.md's ``diagnose`` entry, plus details."""
    out = {
        "verdict": d.verdict,
        "effect": d.effect,
        "effects": list(d.effects),
        "ambiguous_between": list(d.ambiguous_between),
        "candidates": [candidate_dict(c) for c in d.candidates],
        "rounds": [[candidate_dict(c) for c in r] for r in d.rounds],
        "steps": [s.as_dict() for s in d.steps],
        "heldout_rms_before_mm": d.base.heldout_rms_mm,
        "heldout_rms_after_mm": d.final.heldout_rms_mm,
        "noise_floor_mm": d.noise_floor_mm,
        "noise_floor_before_mm": d.noise_floor_base_mm,
        "noise": d.noise.as_dict(),
        "chi2_before": {"chi2": d.base.chi2, "dof": d.base.dof, "p_value": d.base.gof_p},
        "chi2_after": {"chi2": d.final.chi2, "dof": d.final.dof, "p_value": d.final.gof_p},
        "parameters": d.parameters,
        "where": d.where,
        "findings": [f.as_dict() for f in d.findings],
        "absorbed": [n for n, s in d.signatures.items() if s.absorbed],
        "signatures": {
            n: {
                "unabsorbed_min": s.unabsorbed_min,
                "unabsorbed_max": s.unabsorbed_max,
                "absorbed": s.absorbed,
                "partly_absorbed": s.partly_absorbed,
            }
            for n, s in d.signatures.items()
        },
        "confusable": [{"a": a, "b": b, "correlation": c} for a, b, c in d.confusable],
        "poses": {
            "count": d.n_poses,
            "heldout_before_mm": d.base.heldout_errors_mm,
            "heldout_after_mm": d.final.heldout_errors_mm,
            "expected_mm": d.expected_heldout_mm,
        },
        "settings": {
            "folds": d.settings.folds,
            "alpha": d.settings.alpha,
            "gof_alpha": d.settings.gof_alpha,
            "bic_margin": d.settings.bic_margin,
            "min_bic_gain": d.settings.min_bic_gain,
        },
        "advice": advice(d),
        "session": session,
        "rejected_takes": rejected or [],
    }
    return dict(json_safe(out))


def table(headers: list[str], rows: list[list[str]]) -> str:
    """A plain fixed-width table (first column left-aligned, the rest right-aligned)."""
    widths = [
        max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)
    ]

    def line(cells: list[str]) -> str:
        return "  ".join(
            c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
        )

    return "\n".join([line(headers), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def _num(x: float, fmt: str) -> str:
    return "-" if x is None or not np.isfinite(x) else format(x, fmt)


def candidate_rows(candidates: list[Candidate]) -> list[list[str]]:
    return [
        [
            c.name,
            _num(c.p_value, ".2g"),
            _num(c.p_holm, ".2g"),
            _num(c.delta_bic, ".1f"),
            _num(c.heldout_rms_mm, ".3f"),
            _num(c.unabsorbed, ".2f"),
            c.status,
        ]
        for c in candidates
    ]


STEP_HEADERS = ["model", "held-out mm", "noise floor mm", "gap mm", "chi2/dof", "p (added)", "dBIC"]


def step_rows(d: Diagnosis) -> list[list[str]]:
    return [
        [
            " + ".join(("geometry", *s.effects)),
            _num(s.heldout_rms_mm, ".3f"),
            _num(s.noise_floor_mm, ".3f"),
            _num(s.heldout_rms_mm - s.noise_floor_mm, "+.3f"),
            f"{s.chi2:.1f}/{s.dof}",
            _num(s.p_value, ".2g"),
            _num(s.delta_bic, ".1f"),
        ]
        for s in d.steps
    ]


CANDIDATE_HEADERS = ["effect", "p (F)", "p (Holm)", "dBIC", "held-out mm", "unabsorbed", "status"]


def summary_lines(d: Diagnosis) -> list[str]:
    verdict = {
        "named": f"named: {' + '.join(d.effects)}",
        "none": "none: consistent with the base model",
        "ambiguous": f"ambiguous between {', '.join(d.ambiguous_between)}",
        "unexplained": "unexplained: significant disagreement no catalogue effect explains",
    }[d.verdict]
    return [
        f"verdict: {verdict}",
        f"where: {d.where}",
        (
            f"held-out position error (RMS, by pose): before {d.base.heldout_rms_mm:.3f} mm, "
            f"after {d.final.heldout_rms_mm:.3f} mm; noise floor {d.noise_floor_mm:.3f} mm"
        ),
        (
            f"chi2: before {d.base.chi2:.1f} / {d.base.dof} dof (p = {d.base.gof_p:.2g}), "
            f"after {d.final.chi2:.1f} / {d.final.dof} dof (p = {d.final.gof_p:.2g})"
        ),
        f"noise: sigma = {d.noise.typical_mm:.3g} mm RMS per coordinate ({d.noise.source}{'; ' + d.noise.note if d.noise.note else ''})",
    ]


def parameter_rows(d: Diagnosis) -> list[list[str]]:
    rows = []
    for name in d.final.effects:
        p = d.parameters[name]
        for vn, v, s, (lo, hi) in zip(
            p["vector_names"], p["vector"], p["stderr"], p["ci95_vector"]
        ):
            rows.append([f"{name}.{vn}", f"{v:.4g}", _num(s, ".2g"), f"[{lo:.4g}, {hi:.4g}]"])
        for key, ci in p["ci95"].items():
            value = p["table"][key]
            if np.allclose(np.ravel(value), p["vector"]):
                continue  # the profile stores the fitting vector itself
            pairs = list(zip(value, ci)) if isinstance(value, list) else [(value, ci)]
            for i, (v, c) in enumerate(pairs):
                label = f"  {key}" + (f"[{i + 1}]" if len(pairs) > 1 else "")
                rows.append(
                    [
                        label,
                        f"{v:.4g}",
                        "",
                        "[" + ", ".join("inf" if x is None else f"{x:.4g}" for x in c) + "]",
                    ]
                )
    return rows


def to_text(d: Diagnosis, *, session: str = "") -> str:
    parts = [
        f"cdprhost diagnose {session}".rstrip(),
        f"{d.n_poses} poses, {d.settings.folds}-fold held-out error by pose",
        "",
    ]
    parts += summary_lines(d)
    if d.steps:
        parts += [
            "",
            "forward selection: the gap after each step",
            table(STEP_HEADERS, step_rows(d)),
        ]
    for i, rnd in enumerate(d.rounds, start=1):
        parts += [
            "",
            f"round {i}: candidates against {' + '.join(('geometry',) + rnd[0].result.effects[:-1]) if rnd and rnd[0].result else 'the base model'}",
            table(CANDIDATE_HEADERS, candidate_rows(rnd)),
        ]
    absorbed = [n for n, s in d.signatures.items() if s.absorbed]
    if absorbed:
        parts += ["", f"absorbed by the geometry (cannot be named): {', '.join(absorbed)}"]
    if d.confusable:
        parts += [
            "",
            "confusable on these poses: "
            + "; ".join(f"{a} ~ {b} ({c:.2f})" for a, b, c in d.confusable),
        ]
    if d.final.effects:
        parts += [
            "",
            "parameters (95 % intervals)",
            table(["parameter", "value", "stderr", "95 % interval"], parameter_rows(d)),
        ]
    tips = advice(d)
    if tips:
        parts += [""] + [f"note: {t}" for t in tips]
    return "\n".join(parts) + "\n"
