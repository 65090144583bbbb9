"""What the screens say about the device (issue 32): STALE after 2 s and never for a job
that just ended; heaters "from an earlier session" only when they were."""

from __future__ import annotations

from cdprhost.job.state import JobSnapshot, JobState, Temperatures
from cdprhost.machine import Machine, prepare_device
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from cdprhost.tui.state import UiState, shown_temperatures

READING = Temperatures(180.0, 55.0, 0.0, 0.0)


def test_temperatures_are_stale_after_two_seconds():
    state = UiState(job=JobSnapshot(state=JobState.PRINTING, temperatures=READING), temps_at=10.0)
    assert shown_temperatures(state, 11.5).stale_s is None
    assert shown_temperatures(state, 12.6).stale_s == 3  # 5 s before


def test_a_job_that_just_ended_is_not_stale():
    ended = UiState(job=JobSnapshot(state=JobState.DONE, temperatures=READING), temps_at=10.0)
    shown = shown_temperatures(ended, 10.2)
    assert shown.current == (180.0, 55.0) and shown.stale_s is None  # not "STALE 0s"
    assert shown_temperatures(ended, 13.0).stale_s == 3  # and old once it is old


def test_heaters_set_in_this_session_are_not_from_an_earlier_one():
    link = open_embedded()
    try:
        machine = Machine(link, load_profile("paper-prototype"))
        machine.set_heaters(60.0, 40.0)
        notices = prepare_device(machine).notices
        assert not any("earlier session" in n for n in notices), notices
        link.heaters_set.clear()  # as a host that connects later knows nothing of them
        notices = prepare_device(machine).notices
        assert any("earlier session" in n for n in notices), notices
    finally:
        link.close()
