"""Modal dialogs: a yes/no confirmation and the report of a stopped print."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Label, Static

from cdprhost.job.state import Failure
from cdprhost.tui.keys import key_for


class ConfirmScreen(ModalScreen[bool]):
    """Ask before doing something that moves or stops the machine."""

    BINDINGS = [Binding("y", "answer(True)", "Yes"), Binding("n,escape", "answer(False)", "No")]

    def __init__(self, question: str):
        super().__init__(classes="dialog-screen")
        self.question = question

    def compose(self) -> ComposeResult:
        app = self.app
        with Vertical(classes="dialog"):
            yield Label(self.question, classes="dialog-text")
            with Horizontal(classes="dialog-buttons"):
                yes = key_for(app, self, "answer(True)")
                no = key_for(app, self, "answer(False)")
                yield Button(f"Yes ({yes})", variant="primary", id="yes", compact=True)
                yield Button(f"No ({no})", id="no", compact=True)

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)


def failure_text(failure: Failure | None, reason: str, line_text: str, path: str) -> Text:
    """Where a print stopped and how to resume it (pure)."""
    out = Text()
    out.append("The print stopped.\n", style="bold red")
    out.append(f"reason: {failure.reason if failure else reason or 'unknown'}\n")
    if failure is None:
        return out
    if failure.last_line is not None:
        out.append(f"last executed line: {failure.last_line}", style="bold")
        if line_text:
            out.append(f"  {line_text}", style="dim")
        out.append("\n")
    if failure.last_layer is not None:
        out.append(f"last layer: {failure.last_layer + 1} (index {failure.last_layer})\n")
    if failure.position is not None:
        out.append("effector at ({:.2f}, {:.2f}, {:.2f}) mm\n".format(*failure.position))
    if failure.resume_file:
        out.append(f"resume point saved: {failure.resume_file}\n")
    if failure.last_layer is not None:
        later = f"cdprhost print {path} --resume-from-layer {max(failure.last_layer + 1, 1)}"
        if failure.resume_file and failure.last_line:
            later = f"cdprhost print {path} --resume (exactly there), or {later}"
        out.append(f"resume here (after checking the link), or later: {later}", style="italic")
    return out


class FailureScreen(ModalScreen[str]):
    """Shows the stop and the resume point; dismisses with "resume" or "close"."""

    BINDINGS = [
        Binding("r", "choose('resume')", "Resume"),
        Binding("escape,enter", "choose('close')", "Close"),
    ]

    def __init__(self, text: Text, can_resume: bool):
        super().__init__(classes="dialog-screen")
        self.text, self.can_resume = text, can_resume

    def compose(self) -> ComposeResult:
        app = self.app
        with Vertical(classes="dialog failure"):
            yield Static(self.text, id="failure-text")
            with Horizontal(classes="dialog-buttons"):
                if self.can_resume:
                    key = key_for(app, self, "choose('resume')")
                    yield Button(f"Resume ({key})", variant="warning", id="resume", compact=True)
                close = key_for(app, self, "choose('close')")
                yield Button(f"Close ({close})", id="close", compact=True)

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id or "close")

    def action_choose(self, choice: str) -> None:
        if choice == "resume" and not self.can_resume:
            return
        self.dismiss(choice)
