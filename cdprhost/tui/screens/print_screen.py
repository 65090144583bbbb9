"""The print screen: open a file, preflight, run and watch a print."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import Input, Label

from cdprhost.job.state import JobState
from cdprhost.tui.control.jog import static_tensions
from cdprhost.tui.control.source import SourceLines
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.screens.dialogs import FailureScreen, failure_text
from cdprhost.tui.state import UiState, hms, live_position
from cdprhost.tui.widgets.position_panel import PositionPanel
from cdprhost.tui.widgets.progress_panel import ProgressPanel
from cdprhost.tui.widgets.source_view import SourceView
from cdprhost.tui.widgets.temperature_graph import TemperatureGraph
from cdprhost.tui.widgets.tension_bars import TensionBars
from cdprhost.tui.widgets.violation_list import ViolationList


def preflight_summary(state: UiState) -> Text:
    """One line about the open file's preflight (pure)."""
    f = state.file
    if not f.path:
        return Text("no file open: press o and type a G-code path", style="dim")
    if f.checking:
        return Text(f"checking {Path(f.path).name} ...", style="cyan")
    if f.error:
        return Text(f"cannot check {Path(f.path).name}: {f.error}", style="bold red")
    p = f.preflight
    if p is None:
        return Text("")
    out = Text()
    if p.ok:
        out.append("preflight ok", style="bold green")
    else:
        first = min(v.line for v in p.violations) if p.violations else 0
        out.append(
            f"{len(p.violations)} violation{'s' * (len(p.violations) != 1)} (first at line {first})",
            style="bold red",
        )
    out.append(
        f" · {p.moves} moves · {p.layers} layers · est {hms(p.estimated_time_s)} · {p.filament_mm:.0f} mm filament",
        style="dim",
    )
    if p.notes:
        out.append(
            f" · {len(p.notes)} note{'s' * (len(p.notes) != 1)} (harmless commands skipped)",
            style="dim",
        )
    return out


def link_line(state: UiState) -> Text:
    c = state.connection
    health = state.job.link if state.job_active else c.health
    out = Text("link ", style="bold")
    style = {"connected": "green", "connecting": "cyan", "error": "bold red"}.get(c.status, "dim")
    out.append(f"{c.port} {c.status}".strip(), style=style)
    if health is not None:
        out.append(f" · retx {health.retransmits} · bad {health.bad_frames}", style="dim")
    if state.busy:
        out.append(f" · {state.busy}", style="yellow")
    return out


class PrintScreen(AppScreen):
    MODE = "print"
    AUTO_FOCUS = "#violations"
    BINDINGS = [
        Binding("o", "open", "Open"),
        Binding("s", "start", "Start"),
        Binding("p", "pause", "Pause"),
        Binding("r", "resume", "Resume"),
        Binding("x", "cancel", "Cancel"),
        Binding("v", "violations", "Violations", show=False),
        Binding("escape", "leave_input", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="print-screen")
        self.source: SourceLines | None = None
        self._jump: int | None = None

    def compose_body(self) -> ComposeResult:
        statics = self.app.backend.model.statics
        with Horizontal(id="file-row"):
            yield Label("G-code ", id="file-label")
            yield Input(
                placeholder="path to a .gcode file, Enter to check it",
                compact=True,
                id="file-input",
            )
        yield Label(id="preflight-summary")
        with Horizontal(id="panels"):
            with Vertical(id="left-panels"):
                yield ProgressPanel(id="progress")
                yield PositionPanel(id="position")
                yield Label(id="link-line")
            with Vertical(id="right-panels"):
                yield TemperatureGraph(id="temperatures")
                yield TensionBars(statics.t_min, statics.t_max, id="tensions")
        with Horizontal(id="bottom"):
            yield ViolationList(id="violations")
            yield SourceView(id="source")

    def on_mount(self) -> None:
        super().on_mount()

    # ------------------------------------------------------------- render
    def render_state(self, state: UiState) -> None:
        job = state.job
        line_text = self.source.line(job.line) if self.source is not None and job.line else ""
        self.query_one(ProgressPanel).show(job, line_text)
        position, sliders, tensions = live_position(state)
        if tensions is None:
            tensions = static_tensions(self.app.backend.model, position)
        steps = job.steps if state.job_active or state.device is None else state.device.steps
        self.query_one(PositionPanel).show(position, sliders, steps)
        self.query_one(TensionBars).show(tensions)
        self._render_temperatures(state)
        self.query_one("#link-line", Label).update(link_line(state))
        self.query_one("#preflight-summary", Label).update(preflight_summary(state))
        violations = state.file.preflight.violations if state.file.preflight else ()
        table = self.query_one(ViolationList)
        if getattr(table, "_shown", None) is not violations:
            table.show(violations)
            table._shown = violations
        self._render_source(state)

    def _render_temperatures(self, state: UiState) -> None:
        job = state.job
        graph = self.query_one(TemperatureGraph)
        if job.state is not JobState.IDLE and job.temperatures is not None:
            t = job.temperatures
            graph.show(
                (t.hotend, t.bed),
                (t.hotend_target, t.bed_target),
                [(h, b) for _, h, b in job.temperature_history],
            )
        elif state.device is not None:
            d = state.device
            graph.show((d.hotend, d.bed), (d.hotend_target, d.bed_target), state.device_temps)
        else:
            graph.show((None, None), (0.0, 0.0), ())

    def _render_source(self, state: UiState) -> None:
        view = self.query_one(SourceView)
        if self.source is None:
            view.show([], None)
            return
        if state.job_active and state.job.line:
            view.show(self.source.around(state.job.line, 1, 4), state.job.line, "printing")
        elif self._jump is not None:
            pre = state.file.preflight
            why = next(
                (
                    f": {v.rule}: {v.detail}"
                    for v in (pre.violations if pre else ())
                    if v.line == self._jump
                ),
                "",
            )
            view.show(self.source.around(self._jump), self._jump, f"line {self._jump}{why}")
        else:
            view.show(self.source.around(1, 0, 6), None, Path(self.source.path).name)

    # ------------------------------------------------------------- events
    def on_input_submitted(self, event: Input.Submitted) -> None:
        path = event.value.strip()
        if not path:
            return
        self._jump = None
        self.source = None
        self.app.controller.open_file(path)
        self._load_source(path)
        self.query_one(ViolationList).focus()

    @work(thread=True, exclusive=True, group="source")
    def _load_source(self, path: str) -> None:
        try:
            source = SourceLines(path)
        except OSError:
            return
        self.app.call_later_safe(self._source_loaded, path, source)

    def _source_loaded(self, path: str, source: SourceLines) -> None:
        if self.app.state.file.path == path:
            self.source = source
            self.render_state(self.app.state)

    def on_violation_list_jump(self, event: ViolationList.Jump) -> None:
        self._jump = event.line
        self._render_source(self.app.state)

    def show_failure(self) -> None:
        state = self.app.state
        job = state.job
        failure = job.failure
        line = failure.last_line if failure and failure.last_line else job.line
        text = failure_text(
            failure,
            job.reason,
            self.source.line(line) if self.source and line else "",
            state.job_path,
        )
        can_resume = failure is not None and failure.last_layer is not None

        def chosen(choice: str | None) -> None:
            if choice == "resume" and failure is not None:
                self.app.controller.start(resume_from_layer=max(failure.last_layer, 0))

        self.app.push_screen(FailureScreen(text, can_resume), chosen)

    # ------------------------------------------------------------ actions
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        mapping = {
            "start": "start_print",
            "pause": "pause_print",
            "resume": "resume_print",
            "cancel": "cancel_print",
        }
        if action in mapping:
            return self.app.check_print_action(mapping[action])
        return True

    def action_open(self) -> None:
        self.query_one("#file-input", Input).focus()

    def action_leave_input(self) -> None:
        self.query_one(ViolationList).focus()

    def action_violations(self) -> None:
        self.query_one(ViolationList).focus()

    def action_start(self) -> None:
        self.app.action_start_print()

    def action_pause(self) -> None:
        self.app.action_pause_print()

    def action_resume(self) -> None:
        self.app.action_resume_print()

    def action_cancel(self) -> None:
        self.app.action_cancel_print()
