"""Job state, progress bar, layer n/N, wall-clock elapsed and time left (heating
included), current line."""

from __future__ import annotations

import time

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import Label

from cdprhost.job.state import JobSnapshot, JobState
from cdprhost.tui.control.eta import Eta
from cdprhost.tui.state import hms
from cdprhost.tui.widgets.charts import hbar
from cdprhost.tui.widgets.show import show_text

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
WAITING_FOR_REST = {
    JobState.PAUSING: "stopping within the moves sent",
    JobState.CANCELLING: "stopping within the moves sent",
}


def progress_fraction(snap: JobSnapshot) -> float:
    """Done fraction: by segments when the job announced their total, else by planned time
    (of the whole file: a resumed job counts from the time planned before its restart)."""
    return max(snap.fraction, 0.0)


def bar_text(fraction: float, width: int, state: JobState) -> Text:
    """The progress bar: blocks to eighths of a cell, then the percentage."""
    style = "green" if state is JobState.DONE else STATE_STYLE[state].replace("bold ", "")
    cells = max(width - 6, 4)
    done = hbar(fraction, 1.0, cells).rstrip()
    out = Text(done, style=style)
    out.append("─" * (cells - len(done)), style="dim")
    return out.append(f" {100 * fraction:3.0f}%", style="bold")


def clock_time(epoch: float) -> str:
    return time.strftime("%H:%M", time.localtime(epoch))


def _fit(parts: list[Text], width: int | None) -> Text:
    """``parts`` joined by " · ", as many whole parts as fit in ``width`` (never one cut)."""
    out = Text()
    for part in parts:
        sep = " · " if out.plain else ""
        if width and out.cell_len + len(sep) + part.cell_len > width and out.plain:
            break
        out.append(sep, style="dim")
        out.append_text(part)
    return out


def eta_text(
    eta: Eta | None,
    now_wall: float,
    state: JobState,
    left_s: float | None = None,
    width: int | None = None,
) -> Text:
    """ "left 0:12:34 wall-clock · done ≈ 14:05 · heating 0:00:40 · machine time left 0:11:54",
    the most useful first and as many whole parts as ``width`` holds; ``left_s``: the time
    left as shown (smoothed), else the estimate's."""
    if state is JobState.DONE:
        return Text("finished", style="green")
    heating = (
        [Text(f"heating {hms(eta.heating_left_s)}", style="dark_orange")]
        if eta is not None and eta.heating_left_s >= 1
        else []
    )
    if eta is not None and not (state.active or state is JobState.PREFLIGHT):
        takes = Text.assemble(("takes ≈ ", "dim"), (hms(eta.wall_s), "bold"))
        wall = Text.assemble(takes, (" wall-clock", "dim"))
        first = wall if not width or wall.cell_len <= width else takes
        return _fit([first, *heating], width)  # the open file, before it starts
    if eta is None or not (state.active or state is JobState.PREFLIGHT):
        return Text("left --:--:--", style="dim")
    left = eta.wall_s if left_s is None else left_s
    short = Text.assemble(("left ", "dim"), (hms(left), "bold"))
    long = Text.assemble(short, (" wall-clock", "dim"))
    parts = [
        long if not width or long.cell_len + 18 <= width else short,
        Text(f"done ≈ {clock_time(now_wall + left)}"),
        *heating,
        Text(f"machine time left {hms(eta.motion_left_s)}", style="dim"),
    ]
    return _fit(parts, width)


def reason_after(state: JobState, reason: str) -> str:
    """A job's reason as shown after its state's name, without saying the state twice
    ("CANCELLED cancelled", "CANCELLED cancelled: quit" read "CANCELLED", "CANCELLED quit")."""
    text = reason.strip()
    if text.lower().startswith(state.value):
        text = text[len(state.value) :].lstrip(" :;,-")
    return text


def progress_lines(
    snap: JobSnapshot,
    line_text: str,
    shown: JobState | None = None,
    elapsed_s: float | None = None,
    notice: str = "",
    width: int | None = None,
) -> tuple[Text, Text, Text]:
    """The panel's text lines for a snapshot (pure, for tests too): state, layer and
    elapsed wall-clock time, current line. ``shown`` is the state to display (PAUSING while
    a pause waits for a rest point); ``notice``: a recent notice of the job."""
    state = shown or snap.state
    head = Text()
    head.append(f" {state.value.upper()} ", style="reverse " + STATE_STYLE[state])
    if state in WAITING_FOR_REST and state is not snap.state:
        head.append(f" {WAITING_FOR_REST[state]}", style="italic")
    elif reason_after(state, snap.reason):
        head.append(f" {reason_after(state, snap.reason)}", style="italic")
    elif notice:
        head.append(f" {notice}", style="dim italic")
    layers = f"{min(snap.layer + 1, snap.layers)}/{snap.layers}" if snap.layers else "-/-"
    idle = snap.state is JobState.IDLE
    stats = _fit(
        [
            Text.assemble(("layer ", "dim"), layers),
            Text.assemble(("elapsed ", "dim"), hms(None if idle else elapsed_s)),
            Text.assemble(("machine ", "dim"), hms(None if idle else snap.device_time_s)),
        ],
        width,
    )
    cur = Text()
    if snap.line:
        cur.append(f"line {snap.line}: ", style="dim")
        cur.append(line_text)
    return head, stats, cur


class ProgressPanel(Vertical):
    def compose(self) -> ComposeResult:
        yield Label(id="job-state")
        yield Label(id="job-bar")
        yield Label(id="job-stats")
        yield Label(id="job-eta")
        yield Label(id="job-line")

    def show(
        self,
        snap: JobSnapshot,
        line_text: str = "",
        shown: JobState | None = None,
        elapsed_s: float | None = None,
        notice: str = "",
        share_before: float = 0.0,
    ) -> None:
        """``share_before``: the share of the file done before this (resumed) job began."""
        width = self.query_one("#job-stats", Label).content_region.width or None
        head, stats, cur = progress_lines(snap, line_text, shown, elapsed_s, notice, width)
        show_text(self.query_one("#job-state", Label), head)
        show_text(self.query_one("#job-stats", Label), stats)
        show_text(self.query_one("#job-line", Label), cur)
        bar = self.query_one("#job-bar", Label)
        done = share_before + (1.0 - share_before) * progress_fraction(snap)
        show_text(bar, bar_text(done, bar.size.width or 40, snap.state))

    def show_notice(self, snap: JobSnapshot, shown: JobState, notice: str) -> None:
        head, _, _ = progress_lines(snap, "", shown, None, notice)
        show_text(self.query_one("#job-state", Label), head)

    def show_times(
        self,
        snap: JobSnapshot,
        elapsed_s: float | None,
        eta: Eta | None,
        now_wall: float,
        shown: JobState | None = None,
        left_s: float | None = None,
    ) -> None:
        """What changes with the clock alone: elapsed and time left."""
        stats_label = self.query_one("#job-stats", Label)
        width = stats_label.content_region.width or None
        _, stats, _ = progress_lines(snap, "", shown, elapsed_s, "", width)
        show_text(stats_label, stats)
        label = self.query_one("#job-eta", Label)
        width = label.content_region.width or None
        show_text(label, eta_text(eta, now_wall, snap.state, left_s, width))
