"""The wizard's pure state machine: order of actions, retries, skips, resume."""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.planning import PosePlan
from cdprhost.calibration.wizard import (
    Finished,
    IdentifyStep,
    MoveTo,
    PlanMore,
    RecordTake,
    WizardState,
    resume_state,
)


def small_plan(roles=("fit", "fit", "check", "fit", "fit")) -> PosePlan:
    n = len(roles)
    poses = np.column_stack([np.arange(n) * 10.0, np.zeros(n), np.full(n, 200.0)])
    return PosePlan(
        poses, tuple(roles), poses + [0, 0, 5.0], -np.ones((n, 3)), "D", {}, {}, 0.0, 0, 0.0
    )


def test_moves_then_records_each_pose_then_identifies():
    state = WizardState(small_plan())
    seen = []
    for _ in range(20):
        action = state.next_action()
        seen.append(type(action).__name__)
        if isinstance(action, MoveTo):
            np.testing.assert_allclose(action.waypoints[1], state.plan.poses[action.index])
            assert action.waypoints[0][2] == state.plan.poses[action.index][2] + 5.0
            state = state.moved(action.index)
        elif isinstance(action, RecordTake):
            assert action.attempt == 1
            state = state.accepted(action.index)
        elif isinstance(action, IdentifyStep):
            state = state.identified_as(True)
        else:
            break
    assert seen == ["MoveTo", "RecordTake"] * 5 + ["IdentifyStep", "Finished"]
    assert state.next_action() == Finished("identified")


def test_rejected_take_is_recaptured_at_once_then_the_pose_is_skipped():
    state = WizardState(small_plan(), max_attempts=3).moved(0)
    state = state.rejected(0, "drift")
    action = state.next_action()  # move again (a fresh settle), then capture again
    assert isinstance(action, MoveTo) and action.index == 0
    state = state.moved(0)
    assert state.next_action() == RecordTake(0, 2, "drift")
    state = state.rejected(0, "drift again").moved(0)
    assert state.next_action().attempt == 3
    state = state.rejected(0, "still moving")
    assert 0 in state.skipped
    assert isinstance(state.next_action(), MoveTo) and state.next_action().index == 1


def test_refused_identification_plans_more_then_gives_up():
    state = WizardState(small_plan(), max_rounds=1)
    for i in range(5):
        state = state.accepted(i)
    assert state.next_action() == IdentifyStep(0)
    state = state.identified_as(False, "predicted 2 mm")
    assert state.next_action() == PlanMore(1, "predicted 2 mm")
    bigger = small_plan(("fit", "fit", "check", "fit", "fit", "fit"))
    state = state.augmented(bigger)
    action = state.next_action()
    assert isinstance(action, MoveTo) and action.index == 5
    state = state.moved(5).accepted(5)
    assert state.next_action() == IdentifyStep(1)
    state = state.identified_as(False, "still 1.2 mm")
    action = state.next_action()
    assert isinstance(action, Finished) and "refused after 1 augmentation" in action.reason
    done = WizardState(small_plan(), recorded=frozenset(range(5)))
    stuck = done.identified_as(False, "x").augmented(small_plan())
    assert "no pose can be added" in stuck.next_action().reason


def test_too_few_fit_poses_finishes_without_identifying():
    state = WizardState(small_plan())
    for i in range(5):
        state = state.skip(i) if i < 2 else state.accepted(i)
    action = state.next_action()
    assert isinstance(action, Finished) and "2 fit pose(s)" in action.reason


def test_resume_skips_recorded_poses():
    plan = small_plan()
    state = resume_state(plan, ["1", "3", ""])
    assert state.recorded == frozenset({0, 2})
    assert state.pending == [1, 3, 4]
    assert state.next_action().index == 1
