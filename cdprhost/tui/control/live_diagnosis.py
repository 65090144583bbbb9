"""The diagnosis workflow for the diagnose screen: run it, reduce its report to a view."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.kinematics import MachineModel
from cdprhost.tui.control.views import CandidateRow, DiagnosisView


def _num(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) else None


def _fmt(value: Any) -> str:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return f"{float(arr):.4g}"
    return "[" + ", ".join(f"{v:.4g}" for v in arr.ravel()) + "]"


def parameter_rows(report: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    """ "effect.key" -> "value [95 % interval]" for every effect in the final model."""
    rows = []
    params = report.get("parameters") or {}
    for name in report.get("effects") or ():
        entry = params.get(name) or {}
        ci = entry.get("ci95") or {}
        for key, value in (entry.get("table") or {}).items():
            if key.endswith("stderr") or not isinstance(value, (int, float, list, tuple)):
                continue
            interval = (
                f" (95% {_fmt(np.asarray(ci[key])[..., 0])}..{_fmt(np.asarray(ci[key])[..., 1])})"
                if key in ci
                else ""
            )
            rows.append((f"{name}.{key}", _fmt(value) + interval))
    return tuple(rows)


def diagnosis_view(report: dict[str, Any]) -> DiagnosisView:
    """The JSON report of :func:`cdprhost.diagnosis.report.to_json` as the screen shows it."""
    poses = report.get("poses") or {}
    candidates = tuple(
        CandidateRow(
            c["name"],
            _num(c.get("p_value")),
            _num(c.get("delta_bic")),
            _num(c.get("heldout_rms_mm")),
        )
        for c in report.get("candidates") or ()
    )
    before = tuple(float(v) for v in (poses.get("heldout_before_mm") or ()) if v is not None)
    after = tuple(float(v) for v in (poses.get("heldout_after_mm") or ()) if v is not None)
    return DiagnosisView(
        verdict=str(report["verdict"]),
        effect=report.get("effect"),
        where=str(report.get("where") or ""),
        candidates=candidates,
        heldout_rms_before_mm=float(report["heldout_rms_before_mm"]),
        heldout_rms_after_mm=float(report["heldout_rms_after_mm"]),
        noise_floor_mm=float(report["noise_floor_mm"]),
        per_pose_before_mm=before,
        per_pose_after_mm=after,
        parameters=parameter_rows(report),
    )


def run_diagnosis(session_dir: str, model: MachineModel, settings: Any = None) -> DiagnosisView:
    """Blocking: diagnose the session folder against ``model``."""
    return run_diagnosis_kept(session_dir, model, settings)[0]


def run_diagnosis_kept(
    session_dir: str, model: MachineModel, settings: Any = None
) -> tuple[DiagnosisView, Any]:
    """:func:`run_diagnosis`, and the diagnosis itself (to write the improved profile)."""
    from cdprhost.diagnosis.report import to_json
    from cdprhost.diagnosis.session_input import diagnose_session
    from cdprhost.diagnosis.workflow import DiagnosisSettings

    result, _ = diagnose_session(session_dir, model, settings or DiagnosisSettings())
    return diagnosis_view(to_json(result, session=session_dir)), result


class DiagnosedProfile:
    """The last diagnosis of a session and the profile it can improve (the diagnose screen's
    write-back: asked first, written atomically, never over a shipped profile)."""

    def __init__(self) -> None:
        self.session = ""
        self.result: Any = None

    def keep(self, session: str, result: Any) -> None:
        self.session, self.result = session, result

    def plan(self, profile_ref: str) -> Any:
        """Where the improved profile would go (a ``WritePlan``; its ``refused`` says why not)."""
        from cdprhost.diagnosis.write_back import WritePlan, write_plan
        from cdprhost.errors import CdprError
        from cdprhost.profile.loader import resolve_profile_path

        if self.result is None:
            return WritePlan(Path(""), refused="no diagnosis yet: run one first")
        try:
            path = resolve_profile_path(profile_ref)
        except CdprError as exc:
            return WritePlan(Path(""), refused=f"the profile's file is not known: {exc}")
        return write_plan(self.result, path)

    def write(self, profile: Any, profile_ref: str) -> str:
        """Blocking: write it; the path written."""
        from cdprhost.diagnosis.write_back import write_improved

        return str(
            write_improved(profile, self.result, self.plan(profile_ref), session=self.session)
        )
