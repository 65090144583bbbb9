"""The simulated firmware's behaviour, driven through an embedded HostLink (virtual time)."""

from __future__ import annotations

import numpy as np
import pytest

import firmware_protocol.messages as M
from cdprhost.link import DeviceFault, DeviceStatus
from cdprhost.link.events import DeviceEvent
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.messages import ErrorCode
from firmware_protocol.ramp_profile import RAMP_TO_REST
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.streams import demo_stream, expected_record


def test_clean_stream_executes_exactly():
    batch = demo_stream(2000, seed=4)
    link = open_embedded()
    segs = link.queue_segments(batch)
    assert segs == range(1, 2001)
    link.wait_idle()
    assert link.device.record == expected_record(batch)
    status = link.request_status()
    assert status.steps == tuple(link.device.record[-1]["steps"])
    assert status.segments_done == 2000 and status.queue_free == 128
    assert link.device.machine.overflow_rejects == 0


def test_queue_never_overflows_and_capacity_is_announced():
    link = open_embedded(config=SimConfig(queue_capacity=16))
    assert link.identity.queue_capacity == 16
    batch = demo_stream(500, seed=1)
    link.queue_segments(batch)
    link.wait_idle()
    assert link.device.machine.overflow_rejects == 0
    assert link.device.record == expected_record(batch)


def test_underrun_is_reported_with_the_last_segment():
    batch = demo_stream(50, seed=2)
    moving_end = SegmentBatch(
        batch.ticks, batch.deltas, np.full(50, -1)
    )  # last one does not end at rest
    link = open_embedded()
    link.queue_segments(moving_end)
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(timeout=30)
    assert exc.value.code == ErrorCode.UNDERRUN and exc.value.segment == 50
    assert "underrun" in str(exc.value)
    assert len(link.device.record) == 50


def test_motion_waits_for_a_worthwhile_buffer_before_starting():
    link = open_embedded()
    dev = link.device
    link.queue_segments(
        SegmentBatch([2000], [[100, 0, 0, 0]], [0])
    )  # starts from rest, ends moving
    link.poll(0.05)  # less than start_delay: nothing started yet
    assert dev.record == [] and dev.machine.current is None
    link.queue_segments(SegmentBatch([2000], [[100, 0, 0, 0]], [RAMP_TO_REST]))
    link.wait_idle(5)
    assert [r["steps"][0] for r in dev.record] == [100, 200]


def test_step_rate_limit_checked_by_host_and_device():
    link = open_embedded()
    fast = SegmentBatch([100], [[5000, 0, 0, 0]], [RAMP_TO_REST])  # 5000 steps in 1 ms
    with pytest.raises(ValueError, match="peak step rate"):
        link.queue_segments(fast)
    link.send(M.Segment(100, (0, 0, 0, 5000), RAMP_TO_REST))  # bypass the host check
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(5)
    assert exc.value.code == ErrorCode.STEP_RATE and exc.value.axis == 3


def test_endstop_hit_during_motion_stops_at_the_switch():
    cfg = SimConfig()
    link = open_embedded(config=cfg)
    # boot: physical = logical - 8000; the limit is 16400 past the switch
    link.queue_segments(SegmentBatch([100_000], [[30_000, 0, 0, 0]], [RAMP_TO_REST]))
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(10)
    assert (
        exc.value.code == ErrorCode.ENDSTOP_HIT and exc.value.axis == 0 and exc.value.segment == 1
    )
    last = link.device.record[-1]
    assert last["error"] == "endstop_hit"
    assert last["steps"][0] == cfg.overtravel_steps + 1 - cfg.boot_physical[0]


def test_homing_sets_positions_and_reports():
    link = open_embedded()
    link.send(M.Home(0b111, (1000, 2000, 3000)))
    link.wait_idle(30)
    events = link.poll()
    homed = [e for e in events if isinstance(e, DeviceEvent) and e.name == "homed"]
    assert homed and homed[0].values == (1000, 2000, 3000)
    st = link.request_status()
    assert st.steps[:3] == (1000, 2000, 3000) and st.homed_mask == 0b111
    assert st.motion_time_s == pytest.approx(8000 / 4000, abs=1e-4)  # 8000 steps at 4000 steps/s
    # after homing, the endstop limit is relative to the new coordinates
    link.queue_segments(SegmentBatch([200_000], [[20_000, 0, 0, 0]], [RAMP_TO_REST]))
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(10)
    assert (
        exc.value.code == ErrorCode.ENDSTOP_HIT
        and link.device.record[-1]["steps"][0] == 1000 + 16_401
    )


def test_set_position_enable_dwell_fan():
    link = open_embedded()
    n = link.send(
        M.SetPosition((10, 20, 30, 40)), M.Enable(0b1111), M.Dwell(50_000), M.SetFan(0, 128)
    )
    assert n == [1, 2, 3, 4]
    link.queue_segments(SegmentBatch([1000], [[1, 2, 3, 4]], [RAMP_TO_REST]))
    link.wait_idle(5)
    st = link.request_status()
    assert st.steps == (11, 22, 33, 44) and st.fan == 128 and st.enabled_mask == 0b1111
    assert link.device.record == [{"seq": 1, "steps": [11, 22, 33, 44], "t": 0.51}]


def test_heating_and_waiting_for_temperature():
    link = open_embedded()
    link.send(
        M.SetHeater(M.HOTEND, 2100),
        M.SetHeater(M.BED, 600),
        M.WaitHeater(M.HOTEND, 20),
        M.WaitHeater(M.BED, 20),
    )
    link.queue_segments(SegmentBatch([1000], [[1, 0, 0, 0]], [RAMP_TO_REST]))
    link.wait_idle(600)
    st = link.request_status()
    assert st.hotend_c == pytest.approx(210, abs=2.5) and st.bed_c == pytest.approx(60, abs=2.5)
    assert st.hotend_target_c == 210 and st.bed_target_c == 60
    assert link.now() > 20  # it took (virtual) time to heat
    names = [e.name for e in link.poll(20) if isinstance(e, DeviceEvent)]
    assert names.count("heater_reached") == 2


def test_thermal_runaway_is_detected_and_heaters_switch_off():
    link = open_embedded(faults="heater_fail_after=60")
    link.send(M.SetHeater(M.HOTEND, 2100))
    with pytest.raises(DeviceFault) as exc:
        link.wait_idle(None)
        link.poll(300)
    assert exc.value.code == ErrorCode.THERMAL_RUNAWAY and exc.value.axis == M.HOTEND
    assert 60 < link.now() < 60 + 2 * 40 + 5  # within two watch periods (40 s) of the failure
    assert link.device.machine.heaters[0].target == 0


def test_heater_target_over_the_maximum_is_refused():
    link = open_embedded()
    link.send(M.SetHeater(M.BED, 2000))
    with pytest.raises(DeviceFault) as exc:
        link.poll(1)
    assert exc.value.code == ErrorCode.HEATER_RANGE


def test_emergency_stop_mid_segment_then_clear_and_continue():
    link = open_embedded()
    link.queue_segments(
        SegmentBatch([100_000, 100_000], [[10_000, 0, 0, 0], [-10_000, 0, 0, 0]], [0, 255])
    )
    link.poll(0.6)
    assert link.emergency_stop()
    with pytest.raises(DeviceFault):
        link.queue_segments(SegmentBatch([1000], [[1, 0, 0, 0]], [255]))
    rec = link.device.record
    assert len(rec) == 1 and rec[0]["error"] == "estop" and 0 < rec[0]["steps"][0] < 10_000
    st = link.device.status()
    assert st.flags & M.Flag.ESTOP and st.enabled_mask == 1  # the motor kept: it moved
    link.clear_fault()
    link.queue_segments(SegmentBatch([1000, 1000], [[5, 0, 0, 0], [5, 0, 0, 0]], [-1, 255]))
    link.wait_idle(5)
    assert [r["steps"][0] for r in link.device.record[1:]] == [
        rec[0]["steps"][0] + 5,
        rec[0]["steps"][0] + 10,
    ]


def test_observer_is_told_when_motion_settles():
    seen = []

    class Observer:
        def on_settled(self, steps, t):
            seen.append((steps, t))

    link = open_embedded(observer=Observer())
    t0 = link.now()
    link.queue_segments(SegmentBatch([10_000, 10_000], [[100, 0, 0, 0], [0, 50, 0, 0]], [-1, 255]))
    link.wait_idle(5)
    link.poll(0.5)
    assert len(seen) == 1 and seen[0][0] == (100, 50, 0, 0)
    # 0.2 s of motion + 0.2 s settle, after the bytes arrived
    assert t0 + 0.4 <= seen[0][1] <= t0 + 0.45


def test_status_reports_are_parsed():
    link = open_embedded()
    st = link.request_status()
    assert (
        isinstance(st, DeviceStatus)
        and st.steps == (0, 0, 0, 0)
        and st.hotend_c == pytest.approx(25)
    )
    assert st.flags & M.Flag.SYNCED


def test_flow_control_holds_with_reports_interleaved():
    """Device reports carry acknowledgements without flow information; the host's
    credit must still never exceed the device's free slots (a UI thread polls the
    status while the job streams)."""
    import threading
    import time

    link = open_embedded(config=SimConfig(queue_capacity=24))
    batch = demo_stream(1500, seed=8)
    stop = threading.Event()

    def ui():
        while not stop.is_set():
            link.request_status()
            time.sleep(0.002)

    th = threading.Thread(target=ui)
    th.start()
    try:
        link.queue_segments(batch)
        link.wait_idle(120)
    finally:
        stop.set()
        th.join(10)
    assert link.device.machine.overflow_rejects == 0
    assert link.device.record == expected_record(batch)
