"""A thread-safe hand-over of job events from worker threads to the UI thread.

Workers ``put`` events tagged with their job id; the first put after a drain
calls ``wake`` (which posts one message to the app). The UI thread ``drain``s
everything queued, in order, and folds it with the job reducer. So there is one
writer of UI state (the UI thread), events keep their order, a burst costs one
repaint, and events of a job the UI has already left are recognisable by id.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import Any


class EventPump:
    """``urgent(event)``: events the UI shows at once (a state change, a failure): they wake
    it again even when a wake is pending, and set :attr:`urgent` until the next drain."""

    def __init__(self, wake: Callable[[], Any], urgent: Callable[[Any], bool] | None = None):
        self._wake = wake
        self._is_urgent = urgent or (lambda event: False)
        self._items: deque[tuple[int, Any]] = deque()
        self._lock = threading.Lock()
        self._pending = False
        self.urgent = False

    def put(self, job_id: int, event: Any) -> None:
        hurry = self._is_urgent(event)
        with self._lock:
            self._items.append((job_id, event))
            if self._pending and (not hurry or self.urgent):
                return
            self._pending = True
            self.urgent = self.urgent or hurry
        self._wake()

    def sink(self, job_id: int) -> Callable[[Any], None]:
        """An ``on_event`` callback bound to one job id."""
        return lambda event: self.put(job_id, event)

    def drain(self) -> list[tuple[int, Any]]:
        with self._lock:
            items = list(self._items)
            self._items.clear()
            self._pending = False
            self.urgent = False
        return items
