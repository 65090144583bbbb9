"""The gap figure: held-out error by pose before and after, beside the noise floor.

Top: per-pose bars (base model, final model) with the noise floor and each pose's
expected error for a correct model. Bottom: held-out RMS of every first-round
candidate against the base model and the noise floor. Headless (Agg backend).
"""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from cdprhost.diagnosis.workflow import Diagnosis
from cdprhost.fileio.atomic import atomic_open


def gap_figure(d: Diagnosis) -> Figure:
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), gridspec_kw={"height_ratios": [2, 1]})
    n = d.n_poses
    x = np.arange(1, n + 1)
    before = d.base.heldout_errors_mm
    after = d.final.heldout_errors_mm
    label_after = (
        "after (" + " + ".join(d.final.effects) + ")"
        if d.final.effects
        else "after (no effect added)"
    )
    top.bar(
        x - 0.2,
        before,
        width=0.4,
        color="#c0504d",
        label=f"before: RMS {d.base.heldout_rms_mm:.3f} mm",
    )
    if after is not None:
        top.bar(
            x + 0.2,
            after,
            width=0.4,
            color="#4f81bd",
            label=f"{label_after}: RMS {d.final.heldout_rms_mm:.3f} mm",
        )
    top.step(
        x,
        d.expected_heldout_mm,
        where="mid",
        color="0.3",
        lw=1,
        ls=":",
        label="expected from noise, per pose",
        zorder=3,
    )
    top.axhline(
        d.noise_floor_mm, color="k", ls="--", lw=1, label=f"noise floor {d.noise_floor_mm:.3f} mm"
    )
    top.set_xlabel("pose (visiting order)")
    top.set_ylabel("held-out 3D error (mm)")
    top.set_title(
        f"verdict: {d.verdict}"
        + (
            f" ({', '.join(d.effects or d.ambiguous_between)})"
            if d.effects or d.ambiguous_between
            else ""
        )
    )
    top.legend(loc="upper right", fontsize=8)
    top.set_xlim(0.3, n + 0.7)

    cands = d.candidates
    names = ["base"] + [c.name for c in cands]
    values = [d.base.heldout_rms_mm] + [c.heldout_rms_mm for c in cands]
    colors = ["#c0504d"] + [
        "#4f81bd" if c.status == "named" else "#9bbb59" if c.status == "rival" else "0.6"
        for c in cands
    ]
    bottom.bar(np.arange(len(names)), np.nan_to_num(values), color=colors)
    bottom.axhline(d.noise_floor_mm, color="k", ls="--", lw=1)
    bottom.set_xticks(np.arange(len(names)), names, fontsize=8)
    bottom.set_ylabel("held-out RMS (mm)")
    bottom.set_title("first round: base model and each candidate effect", fontsize=9)
    fig.tight_layout()
    return fig


def save_gap_plot(d: Diagnosis, path: str | os.PathLike[str]) -> None:
    fig = gap_figure(d)
    try:
        with atomic_open(path, "wb") as fh:
            fig.savefig(fh, format="png", dpi=110)
    finally:
        plt.close(fig)
