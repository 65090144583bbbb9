"""The TUI's printer refuses a remote start before anything runs when the machine is not idle."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest

from cdprhost.job.state import JobSnapshot, JobState
from cdprhost.server.printer import Refused
from cdprhost.tui.control.upload_bridge import TuiPrinter
from cdprhost.tui.state import ConnectionView, UiState


class NoPreflight:
    def preflight(self, path):
        raise AssertionError("preflight must not run when the start is refused anyway")


def _app(state: UiState) -> SimpleNamespace:
    return SimpleNamespace(state=state, backend=NoPreflight())


CONNECTED = UiState(connection=ConnectionView(status="connected"))


@pytest.mark.parametrize(
    ("state", "words"),
    [
        (UiState(), "not connected"),
        (replace(CONNECTED, busy="homing"), "homing"),
        (
            replace(CONNECTED, job=JobSnapshot(state=JobState.PAUSED), job_path="/x/a.gcode"),
            "busy: paused a.gcode, started by the terminal UI",
        ),
        (
            replace(CONNECTED, job=JobSnapshot(state=JobState.PREFLIGHT), job_path="/x/b.gcode"),
            "b.gcode",
        ),
    ],
)
def test_a_start_is_refused_unless_idle_and_connected(state, words):
    with pytest.raises(Refused, match=words):
        TuiPrinter(_app(state)).check_start(Path("/up/c.gcode"))


def test_a_start_without_a_check_is_refused():
    with pytest.raises(Refused, match="not checked"):
        TuiPrinter(_app(CONNECTED)).start(Path("/up/c.gcode"), "me")
