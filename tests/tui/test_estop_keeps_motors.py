"""The TUI's emergency stop keeps the motors enabled (a cable robot must not drop its
effector), on both devices: the Python model (embedded) and the AVR firmware in simavr."""

from __future__ import annotations

import os

import pytest

from cdprhost.sim import avr_device
from cdprhost.tui.app import ESTOP_KEY
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.live import LiveBackend
from firmware_protocol.messages import Flag
from tests.conformance.device import RawHost, start

from .conftest import make_app, wait_for

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(params=["python", "avr"])
def device(request, tmp_path):
    """(port for the TUI, how to read the device's enable mask after the TUI has gone)."""
    if request.param == "python":
        yield EMBEDDED, None
        return
    if not hasattr(os, "openpty"):
        pytest.skip("needs pseudo-terminals")
    request.getfixturevalue("avr_built")
    dev = start("avr", tmp_path)
    yield dev.path, dev
    dev.stop()


@pytest.fixture(scope="session")
def avr_built():
    missing = avr_device.toolchain_missing()
    if missing:
        pytest.skip(missing)
    avr_device.build()


async def test_the_tui_estop_leaves_the_motors_enabled(device):
    port, avr = device
    backend = LiveBackend("paper-prototype", speedup=None)
    app = make_app(backend, port=port, baud=250000)
    try:
        async with app.run_test(size=(100, 32)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30, what="connected")
            link = backend.machine.link
            assert backend.machine.enable().enabled_mask == 0b1111
            await pilot.press(ESTOP_KEY, ESTOP_KEY)  # armed, then stopped
            await wait_for(
                pilot,
                lambda s: any("EMERGENCY STOP: the device confirmed" in c.text for c in s.console),
                timeout=20,
                what="the e-stop confirmed",
            )
            if avr is None:
                mc = link.device.machine  # type: ignore[attr-defined]
                assert mc.estopped and mc.enabled_mask == 0b1111
                assert mc.heaters[0].target == 0 and mc.heaters[1].target == 0
    finally:
        backend.close()
    if avr is not None:
        host = RawHost(avr.path)
        try:
            host.hello()
            st = host.status()
        finally:
            host.close()
        assert st.flags & Flag.ESTOP and st.enabled_mask == 0b1111  # the effector held
        assert st.hotend_target_dc == 0 and st.bed_target_dc == 0
