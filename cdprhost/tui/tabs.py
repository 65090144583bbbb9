"""The screens of the UI, one tab each: mode, key, labels, what it is for. The app's
bindings, the tab bar, the command palette, the help screen and every message that names a
screen take their words from here."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tab:
    mode: str
    key: str
    label: str
    short: str  # label on a narrow terminal
    help: str


TABS = (
    Tab(
        "connection", "f1", "Link", "Link", "Link: port (listed or typed), connect, device, health"
    ),
    Tab("print", "f2", "Print", "Print", "Print: pick a file, preflight, preview, run a print"),
    Tab("jog", "f3", "Jog", "Jog", "Jog: move with feasibility first, home, motors, heaters"),
    Tab("calibrate", "f4", "Calibrate", "Cal", "Calibrate: poses, takes, identification"),
    Tab("diagnose", "f5", "Diagnose", "Diag", "Diagnose: verdict, where, held-out gap"),
    Tab("console", "f6", "Console", "Cons", "Console: send a command, replies, device errors"),
    Tab("history", "f7", "History", "Hist", "History: past prints; reopen a file"),
)
TAB_OF = {t.mode: t for t in TABS}


def screen_key(mode: str) -> str:
    """How messages name a screen: "the link screen (F1)"."""
    t = TAB_OF[mode]
    return f"the {t.label.lower()} screen ({t.key.upper()})"
