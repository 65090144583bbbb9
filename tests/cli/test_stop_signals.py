"""SIGINT, SIGHUP and SIGTERM reach one callback while a job runs, and only then."""

from __future__ import annotations

import os
import signal

from cdprhost.cli.signals import STOP_SIGNALS, stop_signals


def test_each_stop_signal_calls_back_with_its_name_and_the_old_handlers_return():
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    seen = []
    with stop_signals(seen.append):
        for sig in STOP_SIGNALS:
            os.kill(os.getpid(), sig)
    assert seen == ["SIGINT", "SIGHUP", "SIGTERM"]
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == before
