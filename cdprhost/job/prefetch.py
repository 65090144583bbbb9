"""Run a generator ahead in a thread, so the streaming loop never waits on planning.

The device queue holds well under a second of motion when segments are short;
planning a chunk of moves can take longer. A bounded queue of ready items keeps
the link fed while the next chunk is computed (numpy releases the GIL for most
of that work).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterable, Iterator
from typing import Any

_DONE = object()


class Prefetch:
    def __init__(self, items: Iterable[Any], depth: int = 8):
        self._q: queue.Queue[Any] = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._produce, args=(iter(items),), name="plan-ahead", daemon=True
        )
        self._thread.start()

    def _put(self, item: Any) -> bool:
        while not self._stop.is_set():
            try:
                self._q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _produce(self, it: Iterator[Any]) -> None:
        try:
            for item in it:
                if not self._put(item):
                    return
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            self._put(("__error__", exc))
            return
        self._put(_DONE)

    def wait_filled(self, count: int, timeout: float = 30.0) -> None:
        """Block until ``count`` items are ready (or the producer has finished): a head start
        so the device never drains its queue while the first chunks are still being planned."""
        deadline = time.monotonic() + timeout
        while self._q.qsize() < count and self._thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.005)

    def __iter__(self) -> Iterator[Any]:
        try:
            while True:
                item = self._q.get()
                if item is _DONE:
                    return
                if isinstance(item, tuple) and len(item) == 2 and item[0] == "__error__":
                    raise item[1]
                yield item
        finally:
            self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
