"""SIGINT, SIGHUP and SIGTERM as requests to a running job, never as an abrupt exit.

A print that is interrupted must stop the machine like a cancel (stop within the motion
sent, park, heaters off, resume point saved), whatever sent the signal: Ctrl-C, a closed
terminal, ``kill``. :func:`stop_signals` routes the three signals to one callback for as
long as a job runs; the callback gets the signal's name and decides (the print command
cancels on the first, e-stops on the second). Only the main thread can install handlers:
elsewhere it installs nothing.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGHUP, signal.SIGTERM)


@contextmanager
def stop_signals(on_signal: Callable[[str], None]) -> Iterator[None]:
    """While inside: each of SIGINT, SIGHUP, SIGTERM calls ``on_signal(name)`` (in the main
    thread, between two Python steps: it must not block); the old handlers come back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        on_signal(signal.Signals(signum).name)

    old = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, previous in old.items():
            signal.signal(sig, previous)
