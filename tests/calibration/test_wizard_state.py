"""The wizard's pure state machine: order of actions, retries, skips, resume."""

from __future__ import annotations

import numpy as np

from cdprhost.calibration.planning import PosePlan
from cdprhost.calibration.wizard import (
    Finished,
    Identify,
    MoveTo,
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
        elif isinstance(action, Identify):
            state = state.done()
        else:
            break
    assert seen == ["MoveTo", "RecordTake"] * 5 + ["Identify", "Finished"]
    assert state.next_action() == Finished("identified")


def test_rejected_take_is_asked_again_then_the_pose_is_skipped():
    state = WizardState(small_plan(), max_attempts=3).moved(0)
    state = state.rejected(0, "not static")
    action = state.next_action()
    assert action == RecordTake(0, 2, "not static")
    state = state.rejected(0, "not static again")
    assert state.next_action().attempt == 3
    state = state.rejected(0, "still moving")
    assert 0 in state.skipped
    assert isinstance(state.next_action(), MoveTo) and state.next_action().index == 1


def test_too_few_fit_poses_finishes_without_identifying():
    state = WizardState(small_plan())
    for i in range(5):
        state = state.skip(i) if i < 2 else state.accepted(i)
    action = state.next_action()
    assert isinstance(action, Finished) and "2 fit pose(s)" in action.reason


def test_resume_skips_recorded_poses():
    plan = small_plan()
    rows = [
        {"plan_pose": "1", "t_s": "0"},
        {"plan_pose": "3", "t_s": "5"},
        {"plan_pose": "", "t_s": "9"},
    ]
    state = resume_state(plan, rows)
    assert state.recorded == frozenset({0, 2})
    assert state.pending == [1, 3, 4]
    assert state.next_action().index == 1
