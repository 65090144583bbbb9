"""Idle and paused links in simulated time: no retransmissions from keep-alives, the heater
lease held by a live job and lost by a wedged one, heaters off after host death in every
device state (PROTOCOL.md 2, 3.3)."""

from __future__ import annotations

import pytest

from cdprhost.link import DeviceFault
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.messages import (
    ErrorCode,
    Flush,
    Segment,
    SetHeater,
    SetLimits,
    WaitHeater,
)


def _idle(link, seconds: float, *, job_alive: bool) -> None:
    """``seconds`` of link time driven by the keep-alive thread's own turns (the embedded
    device's clock runs while it waits); with ``job_alive`` the job also polls the link
    every half second, as the TUI and a paused job do."""
    bench = link._t
    end = bench.t + seconds
    polled = bench.t
    while bench.t < end and link._dev.failure is None:
        link.keepalive_step()
        if job_alive and bench.t - polled >= 0.5:
            polled = bench.t
            link.poll(0.0)


@pytest.mark.parametrize("paused", [False, True])
def test_a_clean_idle_or_paused_link_never_retransmits(paused):
    link = open_embedded(speedup=None)
    try:
        if paused:  # heaters kept, the queue held by a heater wait, as in a pause at rest
            link.send(SetHeater(0, 2000), WaitHeater(0, 10))
        before = link.counters
        _idle(link, 60.0, job_alive=paused)
        after = link.counters
        status = link.request_status()
    finally:
        link.close()
    assert after.frames_sent - before.frames_sent > 100  # keep-alives went out
    assert after.retransmits == 0 and after.timeouts == 0
    assert status.device_retransmits == 0
    assert not status.faulted


def test_the_heater_lease_holds_while_the_job_lives_and_lapses_when_it_is_wedged():
    link = open_embedded(speedup=None, heater_lease_s=2.0)
    try:
        link.send(SetHeater(0, 2000))
        _idle(link, 20.0, job_alive=True)
        assert link.request_status().hotend_target_c == 200.0
        # the job wedges; its keep-alive thread still runs (the watchdog stays fed)
        _idle(link, 3.0, job_alive=False)
        dev = link.device
        assert dev.machine.heaters[0].target == 0.0
        assert dev.machine.last_error == ErrorCode.HEATER_LEASE
        with pytest.raises(DeviceFault, match="heater lease"):
            link.poll(0.5)
    finally:
        link.close()


def test_a_watcher_asking_for_status_does_not_hold_a_wedged_jobs_heaters():
    """A screen refreshing temperatures asks for statuses from its own thread: asking is
    not driving, so the lease still lapses when the job stops calling."""
    link = open_embedded(speedup=None, heater_lease_s=2.0)
    try:
        link.send(SetHeater(0, 2000))
        bench = link._t
        end, asked = bench.t + 3.0, bench.t
        while bench.t < end and link._dev.failure is None:
            link.keepalive_step()
            if bench.t - asked >= 0.5:
                asked = bench.t
                link.ask_status()
        assert link.device.machine.heaters[0].target == 0.0
        assert link.device.machine.last_error == ErrorCode.HEATER_LEASE
    finally:
        link.close()


def test_host_death_after_an_underrun_turns_the_heaters_off_within_the_watchdog():
    """A non-thermal fault (UNDERRUN) leaves the heater on; the host then goes silent."""
    link = open_embedded(speedup=None, watchdog_ms=500)
    dev = link.device
    try:
        link.send(SetHeater(0, 1500), Segment(4000, (300, 0, 0, 0), 0), Flush())
        with pytest.raises(DeviceFault, match="underrun"):
            link.wait_idle(10)
        assert dev.machine.heaters[0].target == 150.0  # a non-thermal fault keeps it
        bench = link._t
        silent_from = bench.t  # the host dies: nothing more is read or written
        bench.run_until(silent_from + 0.5 + 0.1)
        assert dev.machine.heaters[0].target == 0.0
        assert dev.machine.last_error == ErrorCode.WATCHDOG
        assert dev.machine.enabled_mask  # motors held: the effector must not drop
    finally:
        link.close()


def test_the_machine_setup_reaches_the_device_at_every_connect():
    from cdprhost.link.device_setup import DeviceSetup

    link = open_embedded(speedup=None)
    try:
        link.set_machine(DeviceSetup(((-100, 100), (-5, 5), (0, 10)), ((0, (1000, 2000, 3000)),)))
        link.request_status()
        limits = link.device.machine.limits.ranges
        assert limits == [(-100, 100), (-5, 5), (0, 10)]
        assert link.device.machine.heaters[0].pid.gains.kd == 3.0
        link.device.machine.limits.ranges[:] = [None] * 3
        link.handshake()  # sent again
        link.request_status()
        assert link.device.machine.limits.ranges[1] == (-5, 5)
        assert link.caps is not None and link.caps.min_segment_ticks == 1
        assert link.health is not None and link.counters.late_pulses == 0
        assert SetLimits(0, -100, 100) in link._session.setup.messages()
    finally:
        link.close()
