"""Job state, progress bar, layer n/N, elapsed and remaining time, current line."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import Label, ProgressBar

from cdprhost.job.state import JobSnapshot, JobState
from cdprhost.tui.state import hms

STATE_STYLE = {
    JobState.IDLE: "dim",
    JobState.PREFLIGHT: "cyan",
    JobState.REFUSED: "bold red",
    JobState.HEATING: "bold dark_orange",
    JobState.PRINTING: "bold green",
    JobState.PAUSING: "yellow",
    JobState.PAUSED: "bold yellow",
    JobState.CANCELLING: "yellow",
    JobState.CANCELLED: "bold yellow",
    JobState.FAILED: "bold red",
    JobState.DONE: "bold green",
}


def progress_fraction(snap: JobSnapshot) -> float:
    """Done fraction: by segments when the job announced their total, else by planned time."""
    if snap.state is JobState.DONE or snap.segments_total:
        return snap.fraction
    if snap.estimated_time_s > 0:
        return min(max(snap.device_time_s / snap.estimated_time_s, 0.0), 1.0)
    return 0.0


def progress_lines(snap: JobSnapshot, line_text: str) -> tuple[Text, Text, Text]:
    """The panel's three text lines for a snapshot (pure, for tests too)."""
    head = Text()
    head.append(f" {snap.state.value.upper()} ", style="reverse " + STATE_STYLE[snap.state])
    if snap.reason:
        head.append(f" {snap.reason}", style="italic")
    elif snap.notices:
        head.append(f" {snap.notices[-1]}", style="dim italic")
    layers = f"{min(snap.layer + 1, snap.layers)}/{snap.layers}" if snap.layers else "-/-"
    stats = Text.assemble(
        ("layer ", "dim"),
        layers,
        ("  elapsed ", "dim"),
        hms(snap.device_time_s if snap.state is not JobState.IDLE else None),
        ("  ETA ", "dim"),
        hms(snap.eta_s if snap.state.active else (0.0 if snap.state is JobState.DONE else None)),
    )
    cur = Text()
    if snap.line:
        cur.append(f"line {snap.line}: ", style="dim")
        cur.append(line_text)
    return head, stats, cur


class ProgressPanel(Vertical):
    def compose(self) -> ComposeResult:
        yield Label(id="job-state")
        yield ProgressBar(total=1000, show_eta=False, id="job-bar")
        yield Label(id="job-stats")
        yield Label(id="job-line")

    def show(self, snap: JobSnapshot, line_text: str = "") -> None:
        head, stats, cur = progress_lines(snap, line_text)
        self.query_one("#job-state", Label).update(head)
        self.query_one("#job-stats", Label).update(stats)
        self.query_one("#job-line", Label).update(cur)
        self.query_one("#job-bar", ProgressBar).update(
            progress=round(1000 * progress_fraction(snap))
        )
