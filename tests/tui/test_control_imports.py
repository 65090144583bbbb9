"""The TUI's controller stands below the app and its screens: nothing in ``tui/control``
imports them, not even for type hints (it sees the app through ``ControllerHost``)."""

from __future__ import annotations

from tests.test_layers import ROOT, imports_of


def test_the_controller_imports_neither_the_app_nor_the_screens():
    upward = [
        f"{path.name}:{line}: {target}"
        for path in sorted(ROOT.joinpath("cdprhost", "tui", "control").glob("*.py"))
        for line, target in imports_of(path)
        if target == "cdprhost.tui.app" or target.startswith("cdprhost.tui.screens")
    ]
    assert not upward, upward
