"""The diagnose screen writes the profile the diagnosis improved: asked first, atomically,
the user's copy of a shipped profile (said in the question)."""

from __future__ import annotations

import shutil

import pytest
from textual.widgets import Input

from cdprhost.diagnosis.workflow import FAST
from cdprhost.profile import load_profile
from cdprhost.profile.loader import SHIPPED_DIR
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.control.service_backend import ServiceBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen
from tests.diagnosis.sessions import write_hidden_session

from .conftest import make_app, shown, wait_for


async def _diagnose(pilot, app, session) -> None:
    await pilot.press("f5", "e")
    app.screen.query_one("#diag-session", Input).value = str(session)
    await pilot.press("enter")
    state = await wait_for(
        pilot, lambda s: s.diagnose.result is not None or s.diagnose.error, timeout=90
    )
    assert state.diagnose.error == "" and state.diagnose.result.verdict == "named"


@pytest.mark.parametrize("backend_class", [LiveBackend, ServiceBackend])
async def test_w_writes_the_improved_profile_after_asking(tmp_path, backend_class):
    """The same with the device in the UI's process and from a TUI on the printer service."""
    profile = tmp_path / "mine.toml"
    shutil.copy(SHIPPED_DIR / "paper-simulation.toml", profile)
    backend = backend_class(str(profile), speedup=None, diagnosis_settings=FAST)
    write_hidden_session(tmp_path / "session", backend.model, "drive_scale", seed=3)
    app = make_app(backend, connect_on_start=False)
    async with app.run_test(size=(100, 32)) as pilot:
        await _diagnose(pilot, app, tmp_path / "session")
        await pilot.press("w")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        assert str(app.screen.question) == f"Write the improved profile to {profile}?"
        assert "Write the improved profile" in await shown(pilot)
        await pilot.press("n")  # no: nothing written
        await pilot.pause(0.2)
        assert not load_profile(profile).effects
        await pilot.press("w")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        await pilot.press("y")
        await wait_for(
            pilot,
            lambda s: any("wrote the improved profile" in c.text for c in s.console),
            timeout=30,
        )
    assert "drive_scale" in load_profile(profile).effects


async def test_a_shipped_profile_goes_to_the_users_folder_and_the_question_says_so(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path / "profiles"))
    shipped = (SHIPPED_DIR / "paper-simulation.toml").read_bytes()
    backend = LiveBackend("paper-simulation", speedup=None, diagnosis_settings=FAST)
    write_hidden_session(tmp_path / "session", backend.model, "drive_scale", seed=3)
    app = make_app(backend, connect_on_start=False)
    async with app.run_test(size=(120, 40)) as pilot:
        await _diagnose(pilot, app, tmp_path / "session")
        await pilot.press("w")
        await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="question")
        assert "is a shipped profile and is not rewritten" in str(app.screen.question)
        await pilot.press("y")
        await wait_for(
            pilot,
            lambda s: any("wrote the improved profile" in c.text for c in s.console),
            timeout=30,
        )
    assert (SHIPPED_DIR / "paper-simulation.toml").read_bytes() == shipped
    assert "drive_scale" in load_profile(tmp_path / "profiles" / "paper-simulation.toml").effects
