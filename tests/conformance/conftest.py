"""One suite, two devices: the Python model and the AVR firmware in simavr.

The AVR half needs the toolchain (`apt-get install -y gcc-avr avr-libc simavr
libsimavr-dev libelf-dev pkg-config`); without it those tests are skipped with
that message. Both devices announce the same clock (100 kHz) and queue size, so
one host plans the same segments for both.
"""

from __future__ import annotations

import os

import pytest

from cdprhost.sim import avr_device
from tests.conformance.device import RawHost, start

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


@pytest.fixture(scope="session")
def avr_built():
    missing = avr_device.toolchain_missing()
    if missing:
        pytest.skip(missing)
    avr_device.build()


@pytest.fixture(params=["python", "avr"])
def kind(request):
    if request.param == "avr":
        request.getfixturevalue("avr_built")
    return request.param


@pytest.fixture
def device_factory(kind, tmp_path):
    started = []

    def make(*args: str):
        dev = start(kind, tmp_path, *args)
        started.append(dev)
        return dev

    yield make
    for dev in started:
        dev.stop()
        # the harness repairs timer interrupts simavr loses; one it could not repair, or a
        # pulse the firmware had no room for, fails the test
        stats = dev.stats()
        assert stats.get("unrepaired", 0) == 0, stats
        assert stats.get("lost_steps", 0) == 0, stats


@pytest.fixture
def host_factory():
    hosts = []

    def make(path: str) -> RawHost:
        h = RawHost(path)
        hosts.append(h)
        return h

    yield make
    for h in hosts:
        h.close()
