"""The calibration wizard as a screen: plan, visit poses, ingest takes, identify."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.widgets import DataTable, Input, Label

from cdprhost.tui.control.views import CalibrationView, IdentificationView
from cdprhost.tui.keys import hint
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import UiState
from cdprhost.tui.widgets.show import show_text

STATUS_STYLE = {
    "planned": "dim",
    "moving": "cyan",
    "settled": "yellow",
    "take ok": "green",
    "rejected": "bold red",
    "skipped": "red",
    "done": "green",
}


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "" if v is None else format(v, fmt)


def stage_text(cal: CalibrationView) -> Text:
    out = Text.assemble(
        ("wizard  ", "bold"), (cal.stage, "bold red" if cal.stage == "error" else "cyan")
    )
    done = sum(p.status in ("take ok", "done") for p in cal.poses)
    if cal.poses:
        out.append(f"  {done}/{len(cal.poses)} poses measured", style="dim")
    if cal.indices:
        out.append("  " + " ".join(f"{k} {v:.3g}" for k, v in cal.indices), style="dim")
    if cal.message:
        out.append(f"\n{cal.message}", style="red" if cal.stage == "error" else "")
    return out


def trust_text(result: IdentificationView) -> Text:
    """The trust gate's verdict, as ``calibrate identify`` decides (pure)."""
    if result.trusted is None:
        return Text("trust gate: not run", style="dim")
    out = Text("trust gate: ", style="bold")
    if result.trusted:
        out.append("trusted", style="bold green")
    else:
        out.append("REFUSED: no profile written (the reasons below)", style="bold red")
    if result.predicted_rms_mm is not None and result.predicted_max_mm is not None:
        out.append(
            f"   predicted workspace error {result.predicted_rms_mm:.3f} mm RMS, "
            f"{result.predicted_max_mm:.3f} mm max",
            style="dim",
        )
    return out


def result_text(result: IdentificationView | None, identify_key: str = "i Identify") -> Text:
    if result is None:
        return Text(
            f"identification: not run yet ({identify_key}, once the fit poses are measured)",
            style="dim",
        )
    out = Text.assemble(
        ("RMS at fit poses ", "bold"),
        f"{result.rms_before_mm:.3f} → ",
        (f"{result.rms_after_mm:.4f} mm", "bold green"),
    )
    if result.check_before_mm is not None and result.check_after_mm is not None:
        out.append(f"   check poses {result.check_before_mm:.3f} → {result.check_after_mm:.4f} mm")
    out.append(f"   {result.iterations} iterations, {result.poses_used} poses", style="dim")
    out.append("\n").append_text(trust_text(result))
    for w in result.warnings:
        out.append(f"\n! {w}", style="yellow")
    if result.profile_path:
        out.append(f"\nprofile written: {result.profile_path}", style="green")
    return out


class CalibrateScreen(AppScreen):
    MODE = "calibrate"
    AUTO_FOCUS = "#poses"
    BINDINGS = [
        Binding("n", "plan", "Plan poses"),
        Binding("m", "move", "Move to next pose"),
        Binding(
            "k", "take", "Take", tooltip="The settled pose's take: a file, or the camera's pictures"
        ),
        Binding("i", "identify", "Identify"),
        Binding("escape", "leave_input", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="calibrate-screen")
        self._offered: tuple[int, str] | None = None

    def compose_body(self) -> ComposeResult:
        with Horizontal(id="calib-settings"):
            yield Label("fit ")
            yield Input("4", type="integer", compact=True, id="fit-poses")
            yield Label(" check ")
            yield Input("3", type="integer", compact=True, id="check-poses")
            yield Label(" session ")
            yield Input(
                placeholder="session folder (new or to resume)", compact=True, id="session-dir"
            )
            yield Label(" markers ")
            yield Input(
                placeholder="new session: a session.toml with its [mocap] (or [camera])",
                compact=True,
                id="mocap",
            )
        with Horizontal(id="camera-settings"):
            yield Label("camera ")
            yield Input(
                placeholder="blank: motion capture takes; or a camera: 0, a URL, sim",
                compact=True,
                id="camera-source",
            )
            yield Label(" intrinsics ")
            yield Input(placeholder="camera.toml", compact=True, id="camera-intrinsics")
        yield Label(id="calib-stage")
        yield DataTable(id="poses", cursor_type="row", zebra_stripes=True)
        with Horizontal(id="take-row"):
            yield Label("take file ")
            yield Input(
                placeholder="motion-capture take of the settled pose, Enter to ingest",
                compact=True,
                id="take-input",
            )
        yield Label(id="calib-result")
        yield DataTable(id="parameters", cursor_type="row", zebra_stripes=True)

    def on_mount(self) -> None:
        poses = self.query_one("#poses", DataTable)
        for name, width in (
            ("#", 3),
            ("role", 5),
            ("x", 8),
            ("y", 8),
            ("z", 8),
            ("status", 9),
            ("detail", 60),
        ):
            poses.add_column(name, width=width)
        params = self.query_one("#parameters", DataTable)
        for name, width in (
            ("parameter", 10),
            ("before", 10),
            ("after", 10),
            ("± stderr", 9),
            ("95% interval", 22),
        ):
            params.add_column(name, width=width)
        super().on_mount()

    def render_state(self, state: UiState) -> None:
        cal = state.calibration
        show_text(self.query_one("#calib-stage", Label), stage_text(cal), layout=True)
        poses = self.query_one("#poses", DataTable)
        if getattr(poses, "_shown", None) != cal.poses:
            cursor = poses.cursor_row
            poses.clear()
            for p in cal.poses:
                style = STATUS_STYLE.get(p.status, "")
                poses.add_row(
                    str(p.index),
                    p.role,
                    *(f"{v:.2f}" for v in p.point),
                    Text(p.status, style=style),
                    p.detail,
                )
            poses._shown = cal.poses  # type: ignore[attr-defined]
            if cal.poses:
                poses.move_cursor(row=min(cursor, len(cal.poses) - 1))
        waiting = self.app.controller.awaiting_take()
        take_row = self.query_one("#take-row")
        if take_row.display != (not cal.camera):
            take_row.display = not cal.camera  # a camera needs no take file
        take_input = self.query_one("#take-input", Input)
        if waiting is not None and waiting.take and self._offered != (waiting.index, waiting.take):
            take_input.value = waiting.take  # offered by the virtual motion capture, once per pose
            self._offered = (waiting.index, waiting.take)
        show_text(
            self.query_one("#calib-result", Label),
            result_text(cal.result, hint(self.app, self, "identify")),
            layout=True,
        )
        params = self.query_one("#parameters", DataTable)
        if getattr(params, "_shown", None) is not cal.result:
            params.clear()
            for r in cal.result.rows if cal.result else ():
                ci = "" if r.ci_low is None else f"[{r.ci_low:.4f}, {r.ci_high:.4f}]"
                params.add_row(r.name, _num(r.before, ".3f"), _num(r.after), _num(r.stderr), ci)
            params._shown = cal.result  # type: ignore[attr-defined]

    # ------------------------------------------------------------ actions
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        state = self.app.state
        cal = state.calibration
        busy = bool(state.busy) or cal.stage in ("planning", "identifying")
        if action == "plan":
            return None if busy or state.job_active else True
        if action == "move":
            ok = (
                state.connected
                and not state.job_active
                and not busy
                and self.app.controller.next_pose() is not None
            )
            return True if ok else None
        if action == "take":
            return True if self.app.controller.awaiting_take() is not None and not busy else None
        if action == "identify":
            measured = sum(p.role == "fit" and p.status in ("take ok", "done") for p in cal.poses)
            return True if measured >= 4 and not busy else None
        return True

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "take-input":
            if event.value.strip():
                self.app.controller.ingest_take(event.value.strip())
                event.input.value = ""
        else:
            self.action_plan()
        self.query_one("#poses").focus()

    def action_leave_input(self) -> None:
        self.query_one("#poses").focus()

    def action_plan(self) -> None:
        try:
            n_fit = int(self.query_one("#fit-poses", Input).value or 4)
            n_check = int(self.query_one("#check-poses", Input).value or 0)
        except ValueError:
            self.app.notify("pose counts must be integers", severity="error")
            return
        if n_fit < 4 or n_check < 0:
            self.app.notify(
                "at least 4 fit poses (12 parameters, 3 cables per pose)", severity="error"
            )
            return
        session = self.query_one("#session-dir", Input).value.strip() or None
        markers = self.query_one("#mocap", Input).value.strip() or None
        camera = self.query_one("#camera-source", Input).value.strip() or None
        if camera is None:
            self.app.controller.plan_calibration(n_fit, n_check, session, markers)
            return
        intrinsics = self.query_one("#camera-intrinsics", Input).value.strip() or None
        self.app.controller.plan_calibration(n_fit, n_check, session, markers, camera, intrinsics)

    def action_move(self) -> None:
        if self.check_action("move", ()):
            self.app.controller.move_to_pose()

    def action_take(self) -> None:
        if self.app.state.calibration.camera:  # the camera takes the pictures itself
            if self.check_action("take", ()):
                self.app.controller.ingest_take("")
            return
        self.query_one("#take-input", Input).focus()

    def action_identify(self) -> None:
        if self.check_action("identify", ()):
            self.app.controller.identify()
