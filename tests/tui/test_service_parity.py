"""What only ``cdprhost tui --in-process`` did and a TUI on the printer service does too:
diagnose writes the profile it improved; the preflight's estimate is for the board the
service holds (what it announced), as with the device in the UI's process."""

from __future__ import annotations

import shutil
import tempfile

import pytest

from cdprhost.diagnosis.workflow import FAST
from cdprhost.profile import load_profile
from cdprhost.profile.loader import SHIPPED_DIR
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.service_backend import ServiceBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen
from tests.diagnosis.sessions import write_hidden_session
from tests.service.inprocess import serve_in_thread

from .conftest import make_app, wait_for
from .test_diagnose_write import _diagnose


@pytest.fixture
def run_dir(monkeypatch, tmp_path):
    """A short private run folder (a socket's path is at most 107 bytes) and state."""
    folder = tempfile.mkdtemp(prefix="svc-", dir="/tmp")
    monkeypatch.setenv("CDPRHOST_RUN", folder)
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


async def test_diagnose_writes_the_improved_profile_from_a_tui_on_the_service(tmp_path):
    profile = tmp_path / "mine.toml"
    shutil.copy(SHIPPED_DIR / "paper-simulation.toml", profile)
    backend = ServiceBackend(str(profile), speedup=None, diagnosis_settings=FAST)
    write_hidden_session(tmp_path / "session", backend.model, "drive_scale", seed=3)
    app = make_app(backend, connect_on_start=False)
    async with app.run_test(size=(100, 32)) as pilot:
        await _diagnose(pilot, app, tmp_path / "session")
        await pilot.press("w")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.press("y")
        await wait_for(
            pilot,
            lambda s: any("wrote the improved profile" in c.text for c in s.console),
            timeout=30,
        )
    assert "drive_scale" in load_profile(profile).effects


def test_the_preflight_estimates_for_the_board_the_service_holds(run_dir, monkeypatch):
    serve_in_thread(monkeypatch)
    backend = ServiceBackend("paper-prototype", speedup=None)
    try:
        assert backend.local._board() is None  # not connected: the profile's own record
        rows = dict(backend.connect(EMBEDDED, 250000))
        board = backend.local._board()
        assert board is not None and board.min_segment_s is not None
        assert f"{board.max_step_rate:,} steps/s" == rows["max step rate"]
        assert board.firmware == rows["firmware"]
        backend.disconnect()
        assert backend.local._board() is None
    finally:
        backend.close()
