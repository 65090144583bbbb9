"""Modal dialogs: a yes/no confirmation and the report of a stopped print."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Static

from cdprhost.job.state import Failure
from cdprhost.tui.control.views import ResumeView
from cdprhost.tui.keys import key_for


class ConfirmScreen(ModalScreen[bool | str]):
    """Ask before doing something that moves or stops the machine: yes (True), no (False),
    or, when offered, one other choice (``other``: its button label; dismisses with "other")."""

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("l", "other", "Other", show=False),
        Binding("n,escape", "answer(False)", "No"),
    ]

    def __init__(self, question: str | Text, other: str = "", yes: str = "Yes"):
        super().__init__(classes="dialog-screen")
        self.question, self.other, self.yes = question, other, yes

    def compose(self) -> ComposeResult:
        app = self.app
        with Vertical(classes="dialog"):
            yield Static(self.question, classes="dialog-text", id="question")
            with Horizontal(classes="dialog-buttons"):
                yes = key_for(app, self, "answer(True)")
                no = key_for(app, self, "answer(False)")
                yield Button(f"{self.yes} ({yes})", variant="primary", id="yes", compact=True)
                if self.other:
                    key = key_for(app, self, "other")
                    yield Button(
                        f"{self.other} ({key})", variant="warning", id="other", compact=True
                    )
                yield Button(f"No ({no})", id="no", compact=True)

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss("other" if event.button.id == "other" else event.button.id == "yes")

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        return bool(self.other) if action == "other" else True

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    def action_other(self) -> None:
        self.dismiss("other")


def start_text(path: str, fault: str, resume: ResumeView | None) -> Text:
    """The start question: the device's fault explained (starting clears it: the operator's
    decision) and a resume point saved for this file (pure)."""
    out = Text(f"Start printing {path} from the beginning?")
    if fault:
        out.append(f"\n\n{fault[0].upper()}{fault[1:]}.", style="bold red")
        out.append(
            "\nStarting clears it. Check the machine first (the nozzle may rest on a part).",
            style="red",
        )
    if resume is not None and not resume.problem:
        where = (
            f"line {resume.last_line} (layer {resume.layer})"
            if resume.exact
            else (f"layer {resume.layer}")
        )
        out.append("\n\nA resume point is saved for this file: ", style="bold yellow")
        out.append(where + (f" ({resume.reason})" if resume.reason else ""))
        out.append("\nResume continues there; a new start replaces it.", style="dim")
    return out


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
