"""The print screen: pick a file, preflight, preview, run and watch a print."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import Label

from cdprhost.job.state import JobState
from cdprhost.tui.control.eta import EtaSmoother
from cdprhost.tui.control.jog import static_tensions
from cdprhost.tui.control.source import SourceLines
from cdprhost.tui.keys import hint
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.screens.dialogs import FailureScreen, failure_text
from cdprhost.tui.screens.file_picker import FilePickerScreen
from cdprhost.tui.state import (
    UiState,
    elapsed,
    for_open_file,
    hms,
    job_eta,
    live_position,
    resumed_share,
    shown_job_state,
    shown_notice,
    shown_temperatures,
)
from cdprhost.tui.tabs import screen_key
from cdprhost.tui.widgets.layer_preview import LayerPreview, PreviewInput
from cdprhost.tui.widgets.position_panel import PositionPanel
from cdprhost.tui.widgets.progress_panel import ProgressPanel
from cdprhost.tui.widgets.show import show_text
from cdprhost.tui.widgets.source_view import SourceView
from cdprhost.tui.widgets.temperature_graph import TemperatureGraph
from cdprhost.tui.widgets.tension_bars import TensionBars
from cdprhost.tui.widgets.violation_list import ViolationList


def preflight_summary(
    state: UiState, open_key: str = "o Open", center_key: str = "c Center part"
) -> Text:
    """One line about the open file's preflight (pure)."""
    f = state.file
    if not f.path:
        return Text(f"no file open: {open_key} picks one (recent files, folders, or a path)")
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
        if p.placement:  # where the part would fit, and the key that centres it
            out.append(f" · {p.placement}: {center_key}", style="yellow")
    out.append(
        f" · {p.moves} moves · {p.layers} layers · machine time {hms(p.estimated_time_s)}"
        f" · {p.filament_mm:.0f} mm filament",
        style="dim",
    )
    if p.notes:
        out.append(
            f" · {len(p.notes)} note{'s' * (len(p.notes) != 1)} (harmless commands skipped)",
            style="dim",
        )
    if p.placement and p.ok:
        out.append(f" · {p.placement} ({center_key} puts it back)", style="dim")
    return out


def resume_line(state: UiState, resume_key: str) -> Text:
    """The saved resume point of the open file, and how to use it (pure)."""
    r = state.file.resume
    out = Text()
    fault = state.device.fault if state.device is not None and not state.job_active else ""
    if fault:
        out.append(fault, style="bold red")
        out.append(" (a start clears it: check the machine first)", style="red")
        if r is not None:
            out.append(" · ")
    if r is None or state.job_active:
        return out
    out.append("resume point ", style="bold yellow")
    if r.exact:
        out.append(f"line {r.last_line} (layer {r.layer})")
    else:
        out.append(f"layer {r.layer}" if r.layer else "no layer")
    if r.reason:
        out.append(f" ({r.reason})", style="dim")
    if r.problem:
        return out.append(f" · cannot resume: {r.problem}", style="red")
    if not state.connected:
        return out.append(f" · connect on {screen_key('connection')} to resume", style="yellow")
    return out.append(f" · {resume_key}", style="bold")


def link_line(state: UiState) -> Text:
    c = state.connection
    health = state.job.link if state.job_active else c.health
    out = Text("link ", style="bold")
    style = {"connected": "green", "connecting": "cyan", "error": "bold red"}.get(c.status, "dim")
    port = "simulator" if c.simulated else c.port
    out.append(f"{port} {c.status}".strip(), style=style)
    if health is not None:
        out.append(f" · retx {health.retransmits} · bad {health.bad_frames}", style="dim")
    if state.busy:
        out.append(f" · {state.busy}", style="yellow")
    return out


def override_line(state: UiState, keys: str = "+/- speed · </> flow") -> Text:
    """The running print's speed and flow overrides and the keys that change them (pure);
    empty without a running print or while both are 100 %."""
    o = state.job.overrides
    if not state.job_active or (o.speed_pct == 100 and o.flow_pct == 100):
        return Text("")
    out = Text("speed ", style="bold")
    out.append(f"{o.speed_pct:g} %", style="yellow" if o.speed_pct != 100 else "")
    out.append(" · flow ", style="bold")
    out.append(f"{o.flow_pct:g} %", style="yellow" if o.flow_pct != 100 else "")
    if o.time_ratio != 1.0 and o.speed_pct != 100:
        out.append(f" · motion left x{o.time_ratio:.2f}", style="dim")
    out.append(f"   {keys}", style="dim")
    return out


PRINT_ACTIONS = {
    "start": "start_print",
    "pause": "pause_print",
    "resume": "resume_print",
    "cancel": "cancel_print",
    "resume_failed": "resume_failed",
}


class PrintScreen(AppScreen):
    MODE = "print"
    AUTO_FOCUS = "#violations"
    BINDINGS = [
        Binding("o", "open", "Open", tooltip="Pick a G-code file: recent, folders, or a path"),
        Binding("s", "start", "Start"),
        Binding(
            "p", "pause", "Pause", tooltip="Within the moves already sent; lifts, heaters kept"
        ),
        Binding("r", "resume", "Resume"),
        Binding(
            "x", "cancel", "Cancel", tooltip="Within the moves already sent, then parks as set"
        ),
        Binding(
            "l",
            "resume_failed",
            "Resume stopped",
            show=False,  # offered on the resume line when the open file has a resume point
            tooltip="A stopped print, at its saved point (else its layer); the link is checked first",
        ),
        Binding("plus", "override('speed', 10)", "Speed +10 %", show=False),
        Binding("minus", "override('speed', -10)", "Speed -10 %", show=False),
        Binding("greater_than_sign", "override('flow', 5)", "Flow +5 %", show=False),
        Binding("less_than_sign", "override('flow', -5)", "Flow -5 %", show=False),
        Binding("v", "toggle_view", "Preview/violations", show=False),
        Binding("left_square_bracket", "layer(-1)", "Layer down", show=False),
        Binding("right_square_bracket", "layer(1)", "Layer up", show=False),
        Binding("f", "follow", "Follow the print", show=False),
        Binding(
            "c",
            "center",
            "Center part",
            show=False,  # offered on the preflight line
            tooltip="Shift the part to the build volume's centre (as --center), or back",
        ),
    ]

    def __init__(self) -> None:
        super().__init__(id="print-screen")
        self.source: SourceLines | None = None
        self._jump: int | None = None
        self._layer: int | None = None  # browsed layer (None: follow the print)
        self._source_path = ""
        self._eta = EtaSmoother()
        self._eta_job = 0

    def compose_body(self) -> ComposeResult:
        backend = self.app.backend
        statics = backend.model.statics
        bed = backend.profile.build_volume.bed_origin
        with Horizontal(id="file-row"):
            yield Label("G-code ", id="file-label")
            yield Label(id="file-name")
        yield Label(id="preflight-summary")
        yield Label(id="resume-line")
        with Horizontal(id="main"):
            with Vertical(id="dash"):
                with Horizontal(id="panels"):
                    with Vertical(id="left-panels"):
                        yield ProgressPanel(id="progress")
                        yield PositionPanel(
                            (float(bed[0]), float(bed[1]), float(bed[2])), id="position"
                        )
                        yield Label(id="link-line")
                        yield Label(id="override-line")
                    with Vertical(id="right-panels"):
                        yield TemperatureGraph(id="temperatures")
                        yield TensionBars(statics.t_min, statics.t_max, id="tensions")
                with Horizontal(id="bottom"):
                    yield LayerPreview(id="preview", classes="preview")
                    yield ViolationList(id="violations")
                    yield SourceView(id="source")
            yield LayerPreview(id="side-preview", classes="preview")  # wide terminals

    # ------------------------------------------------------------- render
    def render_state(self, state: UiState) -> None:
        state = for_open_file(state)
        job = state.job
        app = self.app
        if state.file.path != self._source_path:  # a new file: its text, its first layer
            self._source_path = state.file.path
            self.source, self._jump, self._layer = None, None, None
            if state.file.path:
                self._load_source(state.file.path)
        line_text = self.source.line(job.line) if self.source is not None and job.line else ""
        self.query_one(ProgressPanel).show(
            job,
            line_text,
            shown_job_state(state),
            elapsed(state, app.wall_clock()),
            shown_notice(state, app.clock()),
            resumed_share(state),
        )
        position, sliders, tensions = live_position(state)
        title = "tension (planned)"
        if tensions is None:
            tensions, title = (
                static_tensions(app.backend.model, position),
                "tension here (predicted)",
            )
        steps = job.steps if state.job_active or state.device is None else state.device.steps
        self.query_one(PositionPanel).show(position, sliders, steps)
        self.query_one(TensionBars).show(tensions, title)
        show_text(self.query_one("#link-line", Label), link_line(state))
        overrides = override_line(state)
        show_text(self.query_one("#override-line", Label), overrides)
        self.set_class(bool(overrides.plain), "-override")
        name = Text(state.file.path or "none", style="bold" if state.file.path else "dim")
        name.append(f"   {hint(app, self, 'open')}", style="dim")
        show_text(self.query_one("#file-name", Label), name)
        show_text(
            self.query_one("#preflight-summary", Label),
            preflight_summary(state, hint(app, self, "open"), hint(app, self, "center")),
            layout=True,  # one row, or two on a narrow terminal
        )
        resume = resume_line(state, hint(app, self, "resume_failed"))
        line = self.query_one("#resume-line", Label)
        show_text(line, resume, layout=True)  # wraps: the offer at its end stays seen
        if line.display != bool(resume.plain):
            line.display = bool(resume.plain)
        pre = state.file.preflight
        violations = pre.violations if pre else ()
        table = self.query_one(ViolationList)
        if table.shown is not violations:
            table.show(violations)
            self.set_class(bool(violations), "-violations")
        self._render_source(state)
        self._render_times(state)
        self._render_preview(state)

    def render_tick(self, state: UiState) -> None:
        """What ages: temperatures (stale marking), elapsed and time left, the preview."""
        state = for_open_file(state)
        self._render_times(state)
        self._render_preview(state)

    def _render_times(self, state: UiState) -> None:
        app = self.app
        self._render_temperatures(state)
        eta = job_eta(state, app.backend.machine_rate())
        wall = app.wall_clock()
        panel = self.query_one(ProgressPanel)
        left = None
        if eta is not None and state.job.state in (JobState.HEATING, JobState.PRINTING):
            if self._eta_job != state.job_id:
                self._eta_job = state.job_id
                self._eta.reset()
            left = self._eta.update(app.clock(), eta.wall_s)
        panel.show_times(state.job, elapsed(state, wall), eta, wall, None, left)
        if state.notice_at is not None:  # a notice goes after a while
            panel.show_notice(state.job, shown_job_state(state), shown_notice(state, app.clock()))

    def _render_temperatures(self, state: UiState) -> None:
        t = shown_temperatures(state, self.app.clock())
        self.query_one(TemperatureGraph).show(t.current, t.targets, t.history, t.stale_s)

    def _render_preview(self, state: UiState) -> None:
        pre = state.file.preflight
        toolpath = pre.toolpath if pre is not None else None
        job = state.job
        printing_this = state.job_path == state.file.path and job.state is not JobState.IDLE
        follow = printing_this and job.line > 0
        layer = self._layer if self._layer is not None else (job.layer if follow else 0)
        nozzle = None
        if follow and job.position is not None and toolpath is not None:
            o = toolpath.bed_origin
            nozzle = (job.position[0] - o[0], job.position[1] - o[1])
        title = "browsing ([ ] layers, f follows)" if self._layer is not None else ""
        data = PreviewInput(toolpath, layer, job.line if follow else 0, nozzle, title)
        for preview in self.query(LayerPreview):
            preview.show(data)

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
    def open_path(self, path: str) -> None:
        self.app.controller.open_file(path)

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
            if choice == "resume":
                self.app.controller.resume_failed()

        self.app.push_screen(FailureScreen(text, can_resume), chosen)

    # ------------------------------------------------------------ actions
    def why_not(self, action: str) -> str:
        state = self.app.state
        if action in PRINT_ACTIONS:
            return self.app.why_not_print(PRINT_ACTIONS[action])
        if action in ("open", "center") and state.job_active:
            return "a print is running: wait until it has ended"
        if action == "center" and not state.file.path:
            return "no file open"
        if action == "override" and not state.job_active:
            return "no print is running"
        return super().why_not(action)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in PRINT_ACTIONS:
            return self.app.check_print_action(PRINT_ACTIONS[action])
        if action == "open":
            return None if self.app.state.job_active else True
        if action == "center":
            return bool(self.app.state.file.path) and not self.app.state.job_active
        if action == "override":
            return self.app.state.job_active
        return True

    def action_center(self) -> None:
        if self.check_action("center", ()):
            self.app.controller.toggle_center()

    def action_open(self) -> None:
        if self.app.state.job_active:
            return
        state = self.app.state

        def chosen(path: str | None) -> None:
            if path:
                self.open_path(path)

        start = str(Path(state.file.path).parent) if state.file.path else None
        self.app.push_screen(FilePickerScreen(state.recent, start), chosen)

    def action_toggle_view(self) -> None:
        self.toggle_class("-violations")

    def action_layer(self, step: int) -> None:
        pre = self.app.state.file.preflight
        if pre is None or pre.toolpath is None or pre.toolpath.layers == 0:
            return
        current = self.query_one("#preview", LayerPreview).shown.layer
        self._layer = min(max(current + step, 0), pre.toolpath.layers - 1)
        self._render_preview(self.app.state)

    def action_follow(self) -> None:
        self._layer = None
        self._render_preview(self.app.state)

    def action_start(self) -> None:
        self.app.action_start_print()

    def action_override(self, what: str, step: float) -> None:
        """M220 / M221 from the keys: the running print's speed or flow, up or down."""
        self.app.controller.override_step(what, step)

    def action_pause(self) -> None:
        self.app.action_pause_print()

    def action_resume(self) -> None:
        self.app.action_resume_print()

    def action_cancel(self) -> None:
        self.app.action_cancel_print()

    def action_resume_failed(self) -> None:
        self.app.action_resume_failed()
