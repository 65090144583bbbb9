"""A device that froze and came back: the link says it was lost, then recovers on its own
port with a new session and says so (issue 32)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from cdprhost.link import DeviceSilent, open_link

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


@pytest.mark.timeout(90)
def test_a_frozen_device_that_comes_back_is_recovered():
    dev = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", "--speedup", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        port = dev.stdout.readline().strip()
        link = open_link(port)
        try:
            assert link.request_status() is not None and link.state == "connected"
            assert link.recover() is None  # nothing to recover
            dev.send_signal(signal.SIGSTOP)
            with pytest.raises(DeviceSilent):
                for _ in range(20):
                    link.request_status()
                    time.sleep(0.2)
            assert link.state == "lost"
            assert link.recover() is None  # still frozen: still lost
            assert link.state == "lost"
            dev.send_signal(signal.SIGCONT)
            said = link.recover()
            assert said is not None and said.startswith("link back:") and port in said
            assert link.state in ("connected", "faulted")  # its watchdog may have tripped
            assert link.request_status().received_at > 0
        finally:
            link.close()
    finally:
        dev.send_signal(signal.SIGCONT)
        dev.terminate()
        dev.wait(10)
