import pytest

from cdprhost.job.state import (
    ALLOWED,
    Failure,
    IllegalTransition,
    JobSnapshot,
    JobState,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
    reduce,
)


def run(*events, snap=None):
    snap = snap or JobSnapshot()
    for e in events:
        snap = reduce(snap, e)
    return snap


def test_normal_print_path_with_pause():
    s = run(
        StateChanged(JobState.PREFLIGHT),
        Planned(layers=10, moves=100, estimated_time_s=50.0, filament_mm=12.0, segments=200),
        StateChanged(JobState.HEATING),
        StateChanged(JobState.PRINTING),
        Progress(segments_done=50, line=40, layer=2, device_time_s=10.0),
        StateChanged(JobState.PAUSING),
        StateChanged(JobState.PAUSED),
        StateChanged(JobState.PRINTING),
        Progress(segments_done=200, line=99, layer=9, device_time_s=50.0),
        StateChanged(JobState.DONE),
    )
    assert s.state is JobState.DONE and s.fraction == 1.0 and s.layer == 9 and s.eta_s == 0.0


def test_progress_fraction_and_eta():
    s = run(
        Planned(layers=3, moves=10, estimated_time_s=100.0, filament_mm=1.0, segments=40),
        Progress(segments_done=10, line=5, layer=1, device_time_s=30.0),
    )
    assert s.fraction == pytest.approx(0.25) and s.eta_s == pytest.approx(70.0)


@pytest.mark.parametrize(
    "src", [JobState.DONE, JobState.FAILED, JobState.CANCELLED, JobState.REFUSED]
)
def test_finished_states_are_final(src):
    snap = JobSnapshot(state=src)
    for target in JobState:
        if target is not src:
            with pytest.raises(IllegalTransition):
                reduce(snap, StateChanged(target))


def test_cannot_resume_without_pausing():
    snap = run(StateChanged(JobState.PREFLIGHT), StateChanged(JobState.PRINTING))
    with pytest.raises(IllegalTransition):
        reduce(snap, StateChanged(JobState.PAUSED))


def test_every_state_is_reachable_from_idle():
    seen, frontier = {JobState.IDLE}, [JobState.IDLE]
    while frontier:
        for nxt in ALLOWED[frontier.pop()]:
            if nxt not in seen:
                seen.add(nxt)
                frontier.append(nxt)
    assert seen == set(JobState)


def test_failure_and_temperature_history_are_kept():
    s = run(
        *(Temperatures(20.0 + i, 25.0, 200.0, 0.0) for i in range(700)),
        Failure("link lost", 123, 4),
    )
    assert len(s.temperature_history) == 600 and s.temperature_history[-1][1] == 719.0
    assert s.failure.last_line == 123
