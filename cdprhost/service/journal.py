"""What a front end that attaches late is told: the job's events, compacted.

State changes, the plan and failures are kept in order (a client replays them through the
one reducer and reaches the same state); of the frequent events only what the reducer
keeps: the last notices, the latest progress and link health, the temperature history.
Folding :meth:`Journal.replay` gives the snapshot that folding every event gives, but for
the device times the temperature history is drawn against (the latest one for all).
"""

from __future__ import annotations

from collections import deque

from cdprhost.job.state import HISTORY, Event, LinkHealth, Notice, Progress, Temperatures

KEPT_NOTICES = 50  # as many as the reducer keeps


class Journal:
    def __init__(self) -> None:
        self._chain: list[Event] = []  # state changes, plans, failures: few a job
        self._notices: deque[Notice] = deque(maxlen=KEPT_NOTICES)
        self._progress: Progress | None = None
        self._health: LinkHealth | None = None
        self._temperatures: deque[Temperatures] = deque(maxlen=HISTORY)
        self.count = 0

    def add(self, event: Event) -> None:
        self.count += 1
        if isinstance(event, Progress):
            self._progress = event
        elif isinstance(event, LinkHealth):
            self._health = event
        elif isinstance(event, Temperatures):
            self._temperatures.append(event)
        elif isinstance(event, Notice):
            self._notices.append(event)
        else:
            self._chain.append(event)

    def replay(self) -> list[Event]:
        """The events to fold, in an order the reducer accepts."""
        out: list[Event] = [*self._chain, *self._notices]
        out.extend(self._temperatures)
        if self._health is not None:
            out.append(self._health)
        if self._progress is not None:
            out.append(self._progress)
        return out
