"""Writing the profile a diagnosis improved: only when it did, never over a shipped profile.

A diagnosis improves the profile when it names an effect and the model with it predicts
held-out poses better than the base model (the gap shrinks). The improved profile is the
augmented one (:func:`cdprhost.diagnosis.augment.augmented_profile`), written atomically.
A profile shipped with cdprhost is never rewritten: the improved one goes to the user's
profiles folder under the same name (which then takes precedence), and the plan says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cdprhost.diagnosis.augment import augmented_profile
from cdprhost.diagnosis.workflow import Diagnosis
from cdprhost.profile.loader import SHIPPED_DIR, save_profile, user_profile_dir
from cdprhost.profile.models import MachineProfile


def not_improved(diagnosis: Diagnosis) -> str:
    """Why the diagnosis did not improve the profile ("" when it did)."""
    before = diagnosis.base.heldout_rms_mm
    after = diagnosis.final.heldout_rms_mm
    if diagnosis.verdict != "named" or not diagnosis.effects:
        return f"the verdict is '{diagnosis.verdict}': no effect named, nothing to add"
    if not after < before:
        return (
            f"the held-out error does not shrink with {', '.join(diagnosis.effects)} "
            f"({before:.3f} -> {after:.3f} mm)"
        )
    return ""


def _shipped(path: Path) -> bool:
    try:
        return path.resolve().parent == SHIPPED_DIR.resolve()
    except OSError:
        return False


@dataclass(frozen=True)
class WritePlan:
    """Where the improved profile goes and what to say first (``refused``: not written)."""

    path: Path
    note: str = ""
    refused: str = ""

    def question(self) -> str:
        """The confirmation to ask before writing."""
        return f"Write the improved profile to {self.path}?" + (
            f" {self.note}" if self.note else ""
        )


def write_plan(diagnosis: Diagnosis, profile_path: str | Path) -> WritePlan:
    """Where the improved profile of ``profile_path`` goes (the file itself, or the user's
    copy of a shipped one) and whether it may be written at all."""
    path = Path(profile_path)
    note = ""
    if _shipped(path):
        target = user_profile_dir() / path.name
        note = (
            f"{path.stem} is a shipped profile and is not rewritten: the improved one goes to "
            f"{target}, which takes its place by name"
        )
        path = target
    return WritePlan(path, note, not_improved(diagnosis))


def write_improved(
    profile: MachineProfile, diagnosis: Diagnosis, plan: WritePlan, *, session: str = ""
) -> Path:
    """Write the improved profile where ``plan`` says (atomically); ValueError when the plan
    refused it."""
    if plan.refused:
        raise ValueError(f"not written: {plan.refused}")
    if _shipped(plan.path):
        raise ValueError(f"not written: {plan.path} is a shipped profile")
    plan.path.parent.mkdir(parents=True, exist_ok=True)
    save_profile(augmented_profile(profile, diagnosis, session=session), plan.path)
    return plan.path
