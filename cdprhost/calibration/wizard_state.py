"""The calibration wizard's pure state machine: what to do next, and the state after each outcome.

Actions: :class:`MoveTo` a pose, :class:`RecordTake` there, :class:`IdentifyStep`,
:class:`PlanMore` (the trust gate refused: plan extra poses and ask for them),
:class:`Finished`. A refused take sends the machine to the pose again at once (move
again, capture again), up to ``max_attempts``; then the pose is skipped. Every
transition returns a new state; the shell (:mod:`.wizard`) carries the actions out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.planning import PosePlan

MEASURE, IDENTIFY, AUGMENT, DONE = "measure", "identify", "augment", "done"


@dataclass(frozen=True)
class MoveTo:
    index: int  # 0-based row of the plan
    waypoints: np.ndarray  # (2, 3): the approach point, then the pose


@dataclass(frozen=True)
class RecordTake:
    index: int
    attempt: int  # 1-based
    last_problem: str | None = None


@dataclass(frozen=True)
class IdentifyStep:
    round: int = 0  # 0 for the planned poses, n after the n-th augmentation


@dataclass(frozen=True)
class PlanMore:
    """The trust gate refused ``reason``: plan extra poses (augmentation ``round``)."""

    round: int
    reason: str


@dataclass(frozen=True)
class Finished:
    reason: str


Action = MoveTo | RecordTake | IdentifyStep | PlanMore | Finished


@dataclass(frozen=True)
class WizardState:
    """Where a calibration session stands. Every transition returns a new state."""

    plan: PosePlan
    recorded: frozenset[int] = frozenset()
    skipped: frozenset[int] = frozenset()
    at: int | None = None  # plan row the machine is settled at (and not yet recorded)
    attempts: int = 0
    last_problem: str | None = None
    phase: str = MEASURE
    rounds: int = 0  # augmentations so far
    reason: str = ""
    max_attempts: int = 3
    min_fit_poses: int = 4
    max_rounds: int = 2

    @property
    def pending(self) -> list[int]:
        return [
            i
            for i in range(len(self.plan.poses))
            if i not in self.recorded and i not in self.skipped
        ]

    @property
    def fit_recorded(self) -> int:
        return sum(self.plan.roles[i] == "fit" for i in self.recorded)

    @property
    def identified(self) -> bool:
        return self.phase == DONE and self.reason == "identified"

    def next_action(self) -> Action:
        pending = self.pending
        if pending:
            i = pending[0]
            if self.at != i:
                return MoveTo(i, np.vstack([self.plan.approach[i], self.plan.poses[i]]))
            return RecordTake(i, self.attempts + 1, self.last_problem)
        if self.phase == DONE:
            return Finished(self.reason)
        if self.phase == AUGMENT:
            return PlanMore(self.rounds + 1, self.reason)
        if self.fit_recorded < self.min_fit_poses:
            return Finished(
                f"only {self.fit_recorded} fit pose(s) recorded; {self.min_fit_poses} are needed"
            )
        return IdentifyStep(self.rounds)

    # ----------------------------------------------------------- measuring
    def moved(self, index: int) -> WizardState:
        return dataclasses.replace(self, at=index)

    def accepted(self, index: int) -> WizardState:
        return dataclasses.replace(
            self, recorded=self.recorded | {index}, at=None, attempts=0, last_problem=None
        )

    def rejected(self, index: int, problem: str) -> WizardState:
        """Go to the pose again and capture again, until ``max_attempts``; then skip it."""
        attempts = self.attempts + 1
        if attempts >= self.max_attempts:
            return dataclasses.replace(
                self, skipped=self.skipped | {index}, at=None, attempts=0, last_problem=problem
            )
        return dataclasses.replace(self, at=None, attempts=attempts, last_problem=problem)

    def skip(self, index: int) -> WizardState:
        return dataclasses.replace(
            self, skipped=self.skipped | {index}, at=None, attempts=0, last_problem=None
        )

    # ----------------------------------------------------------- identifying
    def identified_as(self, trusted: bool, reason: str = "") -> WizardState:
        """After identification: done when trusted; else plan more poses while rounds remain."""
        if trusted:
            return dataclasses.replace(self, phase=DONE, reason="identified")
        if self.rounds < self.max_rounds:
            return dataclasses.replace(self, phase=AUGMENT, reason=reason)
        return dataclasses.replace(
            self, phase=DONE, reason=f"refused after {self.rounds} augmentation(s): {reason}"
        )

    def augmented(self, plan: PosePlan) -> WizardState:
        """Measure the poses added to ``plan`` (an extension of this state's plan)."""
        if len(plan.poses) <= len(self.plan.poses):
            return dataclasses.replace(
                self, phase=DONE, reason=f"refused, and no pose can be added: {self.reason}"
            )
        return dataclasses.replace(self, plan=plan, phase=MEASURE, rounds=self.rounds + 1)


def resume_state(
    plan: PosePlan, plan_rows: Sequence[str], max_attempts: int = 3, rounds: int = 0
) -> WizardState:
    """The state after the rows already in poses.csv (their ``plan_pose`` column, 1-based)."""
    done = {int(r) - 1 for r in plan_rows if (r or "").strip()}
    return WizardState(
        plan,
        frozenset(i for i in done if 0 <= i < len(plan.poses)),
        max_attempts=max_attempts,
        rounds=rounds,
    )
