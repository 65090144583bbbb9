"""Choosing a G-code file: recent files, a folder tree of G-code files, or a typed path."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from pathlib import Path

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import DirectoryTree, Input, Label, OptionList
from textual.widgets.option_list import Option

from cdprhost.tui.keys import hint

GCODE_SUFFIXES = (".gcode", ".gco", ".g", ".gc", ".nc")


def shown_path(path: Path) -> str:
    """A folder as the operator reads it: relative to the working folder when inside it,
    else with the home folder as ~."""
    p = path.resolve()
    with contextlib.suppress(ValueError):
        rel = p.relative_to(Path.cwd().resolve())
        return "." if str(rel) == "." else f"./{rel}"
    with contextlib.suppress(ValueError, RuntimeError):
        return f"~/{p.relative_to(Path.home().resolve())}"
    return str(p)


class GcodeTree(DirectoryTree):
    """Folders and G-code files only (hidden entries left out)."""

    def filter_paths(self, paths: Iterable[Path]) -> Iterable[Path]:
        out = []
        for p in paths:
            if p.name.startswith("."):
                continue
            try:
                if p.is_dir() or p.suffix.lower() in GCODE_SUFFIXES:
                    out.append(p)
            except OSError:
                continue
        return out


class FilePickerScreen(ModalScreen[str | None]):
    """Dismisses with the chosen path, or None."""

    BINDINGS = [
        Binding("escape", "close", "Close"),
        Binding("ctrl+r", "focus_recent", "Recent files"),
        Binding("ctrl+t", "focus_tree", "Folder tree"),
        Binding("ctrl+o", "focus_path", "Type a path"),
        Binding("backspace", "up", "Parent folder"),
    ]

    def __init__(self, recent: tuple[str, ...], start: str | None = None):
        super().__init__(classes="dialog-screen")
        self.recent = recent
        self.start = Path(start).expanduser() if start else Path.cwd()
        if not self.start.is_dir():
            self.start = self.start.parent if self.start.parent.is_dir() else Path.cwd()

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog picker"):
            yield Label("Open a G-code file", classes="section-title")
            yield Input(
                placeholder="path to a .gcode file (Enter opens it)", compact=True, id="file-input"
            )
            with Horizontal(id="picker-body"):
                with Vertical(id="picker-recent"):
                    yield Label("Recent", classes="section-title")
                    yield OptionList(
                        *(Option(Text(self._recent_label(p)), id=p) for p in self.recent),
                        id="recent-list",
                        compact=True,
                    )
                with Vertical(id="picker-tree"):
                    yield Label(shown_path(self.start), id="tree-root", classes="section-title")
                    yield GcodeTree(self.start, id="file-tree")
            yield Label(id="picker-hint", classes="hint")

    @staticmethod
    def _recent_label(path: str) -> str:
        p = Path(path)
        return f"{p.name}  {shown_path(p.parent)}"

    def on_mount(self) -> None:
        app = self.app
        keys = "  ".join(
            hint(app, self, a) for a in ("focus_recent", "focus_tree", "focus_path", "up", "close")
        )
        self.query_one("#picker-hint", Label).update(keys)
        if self.recent:
            self.query_one("#recent-list", OptionList).highlighted = 0
            self.query_one("#recent-list").focus()
        else:
            self.query_one("#file-input").focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        """A file opens; a folder is shown in the tree (relative to the tree's folder)."""
        event.stop()
        path = event.value.strip()
        if not path:
            return
        typed = Path(path).expanduser()
        if not typed.exists() and not typed.is_absolute():  # relative to the tree's folder
            beside = Path(self.query_one(GcodeTree).path) / typed
            typed = beside if beside.exists() else typed
        if typed.is_dir():
            self.show_folder(typed)
            event.input.value = ""
            self.query_one("#file-tree").focus()
            return
        self.dismiss(str(typed))

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        event.stop()
        if event.option.id:
            self.dismiss(event.option.id)

    def on_directory_tree_file_selected(self, event: DirectoryTree.FileSelected) -> None:
        event.stop()
        self.dismiss(str(event.path))

    def action_close(self) -> None:
        self.dismiss(None)

    def action_focus_recent(self) -> None:
        self.query_one("#recent-list").focus()

    def action_focus_tree(self) -> None:
        self.query_one("#file-tree").focus()

    def action_focus_path(self) -> None:
        self.query_one("#file-input").focus()

    def action_up(self) -> None:
        """Show the parent folder in the tree (Backspace, outside the path field)."""
        self.show_folder(Path(self.query_one(GcodeTree).path).resolve().parent)

    def show_folder(self, folder: Path) -> None:
        folder = folder.resolve()
        self.query_one(GcodeTree).path = folder
        self.query_one("#tree-root", Label).update(shown_path(folder))
