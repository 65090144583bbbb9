"""The Calibrate screen's wizard as an operator runs it, for the UI tests on either backend
(the device in the UI's process, or the printer service's): a hidden true machine for the
virtual motion capture, the whole motion-capture wizard to a written profile, and the
camera's first pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from textual.widgets import Input

from cdprhost.profile import MachineProfile, save_profile
from cdprhost.tui.state import UiState
from tests.conftest import PAPER_TRUTH_OUTLETS

from .conftest import wait_for


def save_hidden_truth(nominal: MachineProfile, path: Path) -> Path:
    """A true machine ``nominal`` does not know (its outlets moved), saved at ``path``."""
    lengths = np.linalg.norm(np.array([0.0, 0.0, 330.0]) - PAPER_TRUTH_OUTLETS, axis=1)
    save_profile(nominal.with_geometry(PAPER_TRUTH_OUTLETS, lengths, name="hidden-truth"), path)
    return path


def write_markers(path: Path, profile_name: str) -> Path:
    """A session.toml's markers (``[mocap]``) that read the virtual motion capture's takes,
    for a new session on a device whose motion capture the UI does not know."""
    import tomli_w

    from cdprhost.sim.virtual_mocap import mocap_config

    table = mocap_config(profile_name).mocap.model_dump(mode="json", exclude_none=True)
    session = {"session": {"profile": profile_name}, "mocap": table}
    path.write_text(tomli_w.dumps(session), encoding="utf-8")
    return path


async def mocap_wizard(pilot, session: Path, n_check: int = 2) -> UiState:
    """Plan 4 fit and ``n_check`` check poses into ``session``, move to each, take the take
    the virtual motion capture offers, identify; the state once identified."""
    await pilot.press("f4")
    screen = pilot.app.screen
    screen.query_one("#check-poses", Input).value = str(n_check)
    screen.query_one("#session-dir", Input).value = str(session)
    await pilot.press("n")
    state = await wait_for(pilot, lambda s: s.calibration.stage in ("planned", "error"), 60)
    assert state.calibration.stage == "planned", state.calibration.message
    n = len(state.calibration.poses)
    assert n == 4 + n_check and sum(p.role == "check" for p in state.calibration.poses) == n_check
    for k in range(1, n + 1):
        await pilot.press("m")
        await wait_for(
            pilot,
            lambda s, k=k: (
                s.calibration.poses[k - 1].status in ("settled", "error")
                or s.calibration.stage == "error"
            ),
            timeout=60,
            what=f"pose {k} settled",
        )
        assert pilot.app.state.calibration.stage != "error", pilot.app.state.calibration.message
        await pilot.pause()
        take = screen.query_one("#take-input", Input)
        assert take.value.endswith(f"take-{k:04d}.csv")  # offered by the virtual motion capture
        await pilot.press("k", "enter")
        state = await wait_for(
            pilot,
            lambda s, k=k: s.calibration.poses[k - 1].status != "settled" and not s.busy,
            timeout=30,
        )
        pose = state.calibration.poses[k - 1]
        assert pose.status == "take ok", pose.detail
    await pilot.press("i")
    return await wait_for(pilot, lambda s: s.calibration.stage in ("done", "error"), timeout=60)


async def camera_first_pose(
    pilot, session: Path, camera: str, intrinsics: Path, n_check: int = 0
) -> UiState:
    """Plan with ``camera`` taking the pictures, move to the first pose and take it; the
    state once the take is judged."""
    await pilot.press("f4")
    screen = pilot.app.screen
    screen.query_one("#fit-poses", Input).value = "4"
    screen.query_one("#check-poses", Input).value = str(n_check)
    screen.query_one("#session-dir", Input).value = str(session)
    screen.query_one("#camera-source", Input).value = camera
    screen.query_one("#camera-intrinsics", Input).value = str(intrinsics)
    await pilot.press("n")
    state = await wait_for(pilot, lambda s: s.calibration.stage in ("planned", "error"), 120)
    assert state.calibration.stage == "planned", state.calibration.message
    assert state.calibration.camera == camera
    assert not screen.query_one("#take-row").display  # no take file with a camera
    await pilot.press("m")
    await wait_for(
        pilot,
        lambda s: s.calibration.poses[0].status == "settled" or s.calibration.stage == "error",
        timeout=60,
        what="pose 1 settled",
    )
    await pilot.press("k")  # the camera takes the pictures
    return await wait_for(
        pilot,
        lambda s: s.calibration.poses[0].status != "settled" and not s.busy,
        timeout=120,
        what="pose 1 measured",
    )
