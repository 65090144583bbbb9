"""The calibrate screen takes a camera instead of motion capture, as `calibrate wizard --camera`
does: the simulated camera watching the embedded simulated device takes the pictures of each
settled pose (no take file)."""

from __future__ import annotations

from textual.widgets import Input

from cdprhost.calibration.camera.config import intrinsics_toml
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import true_intrinsics
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.control.live_camera import sim_size

from .conftest import make_app, wait_for

SIZE = (960, 540)


async def test_the_camera_choice_plans_visible_poses_and_takes_pictures(tmp_path):
    intrinsics = tmp_path / "camera.toml"
    intrinsics.write_text(intrinsics_toml(true_intrinsics(rig_for_size(SIZE))), encoding="utf-8")
    backend = LiveBackend("paper-simulation", speedup=None)
    app = make_app(backend)
    async with app.run_test(size=(110, 34)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await pilot.press("f4")
        screen = app.screen
        screen.query_one("#fit-poses", Input).value = "4"
        screen.query_one("#check-poses", Input).value = "0"
        screen.query_one("#session-dir", Input).value = str(tmp_path / "session")
        screen.query_one("#camera-source", Input).value = f"sim:{SIZE[0]}x{SIZE[1]}"
        screen.query_one("#camera-intrinsics", Input).value = str(intrinsics)
        await pilot.press("n")
        state = await wait_for(
            pilot, lambda s: s.calibration.stage in ("planned", "error"), timeout=120
        )
        assert state.calibration.stage == "planned", state.calibration.message
        assert state.calibration.camera == f"sim:{SIZE[0]}x{SIZE[1]}"
        assert not screen.query_one("#take-row").display  # no take file with a camera
        await pilot.press("m")
        await wait_for(
            pilot,
            lambda s: s.calibration.poses[0].status == "settled" or s.calibration.stage == "error",
            timeout=60,
            what="pose 1 settled",
        )
        await pilot.press("k")  # the camera takes the pictures
        state = await wait_for(
            pilot,
            lambda s: s.calibration.poses[0].status != "settled" and not s.busy,
            timeout=120,
            what="pose 1 measured",
        )
        assert state.calibration.poses[0].status == "take ok", state.calibration.poses[0].detail
    assert (tmp_path / "session" / "takes" / "pose_0001" / "frame_1.jpg").is_file()


def test_a_simulated_camera_size_out_of_bounds_is_refused():
    import pytest

    from cdprhost.errors import InputError

    assert sim_size("sim") == (1280, 720) and sim_size("0") is None
    with pytest.raises(InputError, match="outside"):
        sim_size("sim:100000x100000")
