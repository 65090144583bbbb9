"""A device reset or stall mid-stream stops the host quickly and names the last executed segment."""

from __future__ import annotations

import pytest

from cdprhost.link import DeviceReset, DeviceSilent
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.streams import demo_stream


@pytest.mark.parametrize(
    "faults", ["reset_after=1234", "reset_after=1234,corrupt=0.001,drop=0.001,latency_ms=3,seed=2"]
)
def test_reset_mid_stream_is_detected_within_one_second(faults):
    link = open_embedded(faults=faults)
    with pytest.raises(DeviceReset) as exc:
        link.queue_segments(demo_stream(5000, seed=1))
        link.wait_idle()
    dev = link.device
    assert exc.value.last_segment == 1234 and exc.value.exact
    assert dev.record[-1]["seq"] == 1234 and len(dev.record) == 1234
    (reset_at,) = dev.reset_times
    assert 0 <= link.now() - reset_at <= 1.0  # device time == link time here (speedup 1)
    assert "last executed segment 1234" in str(exc.value)
    with pytest.raises(DeviceReset):  # sticky
        link.poll()


def test_host_can_reconnect_after_a_reset():
    link = open_embedded(faults="reset_after=100")
    with pytest.raises(DeviceReset):
        link.queue_segments(demo_stream(300, seed=1))
        link.wait_idle()
    ident = link.handshake()
    assert ident.boot_id == link.device.boot_id
    link.queue_segments(demo_stream(10, seed=2))
    link.wait_idle()
    assert [r.get("boot") for r in link.device.record[-10:]] == [1] * 10


def test_stalled_device_is_reported_silent():
    link = open_embedded(faults="stall_after=500", timeout_s=1.0)
    with pytest.raises(DeviceSilent) as exc:
        link.queue_segments(demo_stream(3000, seed=1))
        link.wait_idle()
    assert len(link.device.record) == 500
    assert 490 <= exc.value.last_segment <= 500
    assert "no answer" in str(exc.value)
