"""Render print-job events on a terminal: a rich progress bar, or plain lines when piped."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    TaskID,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
)

from cdprhost.job.state import Event, Failure, JobSnapshot, JobState, Notice, StateChanged, reduce


def _fmt_s(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    s = int(seconds)
    return f"{s // 3600:d}:{s % 3600 // 60:02d}:{s % 60:02d}"


class ProgressView:
    """Folds events into a snapshot and shows it. Call ``update`` from one thread only."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.console = Console(file=self.stream, highlight=False)
        self.snapshot = JobSnapshot()
        self.live = self.console.is_terminal
        self._bar: Progress | None = None
        self._task: TaskID | None = None
        self._last_plain = -1.0
        self._t0 = time.monotonic()

    def __enter__(self) -> ProgressView:
        if self.live:
            self._bar = Progress(
                TextColumn("[bold]{task.fields[state]:<10}"),
                BarColumn(),
                TaskProgressColumn(),
                TextColumn("layer {task.fields[layer]}"),
                TextColumn("line {task.fields[line]}"),
                TimeElapsedColumn(),
                TextColumn("ETA {task.fields[eta]}"),
                console=self.console,
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task(
                "print", total=1.0, state="", layer="-", line="-", eta="--:--"
            )
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar:
            self._render()
            self._bar.stop()

    def update(self, event: Event) -> None:
        self.snapshot = reduce(self.snapshot, event)
        if (
            isinstance(event, StateChanged)
            and event.reason
            and event.state
            in (JobState.REFUSED, JobState.FAILED, JobState.PAUSED, JobState.HEATING)
        ):
            self._say(f"{event.state.value}: {event.reason}")
        elif isinstance(event, Notice):
            self._say(event.text)
        elif isinstance(event, Failure):
            # the event's layer is the 0-based index (as in Progress); people count from 1
            layer = (
                f", layer {event.last_layer + 1}"
                if event.last_layer is not None and event.last_layer >= 0
                else ""
            )
            where = f"line {event.last_line}{layer}" if event.last_line else "before any motion"
            pos = (
                ""
                if event.position is None
                else "; position (" + ", ".join(f"{v:.2f}" for v in event.position) + ")"
            )
            saved = f"; resume point: {event.resume_file}" if event.resume_file else ""
            self._say(f"stopped at {where}{pos}{saved}")
        self._render()

    def say(self, text: str) -> None:
        """A line above the progress display."""
        self._say(text)

    def _say(self, text: str) -> None:
        if self._bar:
            self._bar.console.print(text)
        else:
            print(text, file=self.stream, flush=True)

    def _render(self) -> None:
        s = self.snapshot
        shown = str(s.layer + 1) if s.layer >= 0 and s.line else "-"
        layer = f"{shown}/{s.layers}" if s.layers > 0 else shown
        if self._bar and self._task is not None:
            self._bar.update(
                self._task,
                completed=s.fraction,
                state=s.state.value,
                layer=layer,
                line=s.line or "-",
                eta=_fmt_s(s.eta_s),
            )
            return
        pct = round(s.fraction * 100)
        if (
            s.state in (JobState.PRINTING, JobState.DONE)
            and (pct >= self._last_plain + 10 or s.state is JobState.DONE)
            and pct != self._last_plain
        ):
            self._last_plain = pct
            now = time.monotonic()  # the service's clock too (one monotonic clock a machine)
            elapsed = s.elapsed_s(now) if s.started_at is not None else now - self._t0
            print(
                f"{s.state.value:<9} {pct:3d}%  layer {layer}  line {s.line}  elapsed {_fmt_s(elapsed)}  "
                f"ETA {_fmt_s(s.eta_s)} (device time)",
                file=self.stream,
                flush=True,
            )
