"""Updating text widgets cheaply: nothing when the text is the same, and no layout pass for
widgets whose size is fixed by the style sheet (a layout pass reflows the whole screen)."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static


def show_text(widget: Static, content: Text | str, *, layout: bool = False) -> None:
    """Show ``content`` in ``widget``; ``layout`` for widgets sized by their content."""
    if getattr(widget, "_shown_content", None) == content:
        return
    widget._shown_content = content  # type: ignore[attr-defined]
    widget.update(content, layout=layout)
