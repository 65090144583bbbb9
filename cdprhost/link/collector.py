"""Python's cyclic garbage collector kept from pausing a stream longer than the device's lead.

A full collection scans every object the process tracks, and every thread waits for it
(the GIL): about 20 ms for the 40,000 objects of `bench/stream_rates.py`'s process, more in
a print's. A device fed short segments holds no more than its queue's slots ahead (the AVR
with the step engine: 64 items, about 40 ms at 1,600 segments/s), so one collection at the
wrong moment let it run dry: the host sent nothing for 25 ms (a generation-2 collection
inside the feed) and the device stopped with UNDERRUN, in about one 30 s stream in three.

While a stream runs (:func:`quiet_collection`, the job's and :meth:`HostLink.queue_segments`'s),
the objects the process holds are frozen (``gc.freeze``: left out of every collection, still
freed by reference counting when they are no longer used) and, every :data:`REFREEZE_S`, the
young ones collected and what is left frozen too (:func:`keep_pauses_short`, the feed's turn):
a collection then scans only what the last few seconds made. When the last stream of the
process ends, everything is thawed for the collector again (a cycle that became garbage while
frozen is collected then). Quiet sections nest and may run in several threads at once.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

#: seconds between two freezes of what a stream made meanwhile: a collection scans at most
#: that much of the process's objects (a young collection before each: about a millisecond)
REFREEZE_S = 2.0

_lock = threading.Lock()
_streams = 0
_frozen_at = 0.0


@contextmanager
def quiet_collection(clock: Callable[[], float] = time.monotonic) -> Iterator[None]:
    """Streaming inside: collections scan only what it made lately (module docstring)."""
    global _streams, _frozen_at
    with _lock:
        if _streams == 0:
            # the young generations only: the device may be moving already (another
            # stream's segments), and a full collection is the pause this avoids
            gc.collect(1)
            gc.freeze()
            _frozen_at = clock()
        _streams += 1
    try:
        yield
    finally:
        with _lock:
            _streams -= 1
            if _streams == 0:
                gc.unfreeze()


def keep_pauses_short(clock: Callable[[], float] = time.monotonic) -> None:
    """Inside a quiet section, every REFREEZE_S: the young generations collected and what
    survives frozen. Outside one: nothing."""
    global _frozen_at
    if not _streams:
        return
    now = clock()
    if now - _frozen_at < REFREEZE_S:
        return
    with _lock:
        if _streams and now - _frozen_at >= REFREEZE_S:
            gc.collect(1)
            gc.freeze()
            _frozen_at = now


def streaming() -> bool:
    """A quiet section is open (for tests and reports)."""
    return _streams > 0
