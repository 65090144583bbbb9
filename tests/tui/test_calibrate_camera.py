"""The calibrate screen takes a camera instead of motion capture, as `calibrate wizard --camera`
does: the simulated camera watching the embedded simulated device takes the pictures of each
settled pose (no take file)."""

from __future__ import annotations

from cdprhost.calibration.camera.config import intrinsics_toml
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import true_intrinsics
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.control.live_camera import sim_size

from .conftest import make_app, wait_for
from .wizard_steps import camera_first_pose

SIZE = (960, 540)


async def test_the_camera_choice_plans_visible_poses_and_takes_pictures(tmp_path):
    intrinsics = tmp_path / "camera.toml"
    intrinsics.write_text(intrinsics_toml(true_intrinsics(rig_for_size(SIZE))), encoding="utf-8")
    backend = LiveBackend("paper-simulation", speedup=None)
    app = make_app(backend)
    async with app.run_test(size=(110, 34)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        camera = f"sim:{SIZE[0]}x{SIZE[1]}"
        state = await camera_first_pose(pilot, tmp_path / "session", camera, intrinsics)
        assert state.calibration.poses[0].status == "take ok", state.calibration.poses[0].detail
    assert (tmp_path / "session" / "takes" / "pose_0001" / "frame_1.jpg").is_file()


def test_a_simulated_camera_size_out_of_bounds_is_refused():
    import pytest

    from cdprhost.errors import InputError

    assert sim_size("sim") == (1280, 720) and sim_size("0") is None
    with pytest.raises(InputError, match="outside"):
        sim_size("sim:100000x100000")
