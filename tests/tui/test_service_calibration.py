"""The Calibrate screen's wizard with the TUI a client of the printer service (no
``--in-process``): its moves run in the service's device session, the virtual motion
capture and the simulated camera watch the service's embedded device, and the planning,
the takes' judging and the fit run in the UI. On the embedded device (the service in a
thread) and on a pty sim-device (the service in its own process); a faulted device
refuses calibrate through the service, with the way out."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from textual.widgets import Input

from cdprhost.calibration.camera.config import intrinsics_toml
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import true_intrinsics
from cdprhost.tui.control.service_backend import ServiceBackend
from tests.e2e.processes import SimDeviceProcess, wait_until
from tests.service.inprocess import serve_in_thread

from .conftest import make_app, wait_for
from .wizard_steps import camera_first_pose, mocap_wizard, save_hidden_truth, write_markers


@pytest.fixture
def truth(sim_profile, tmp_path) -> Path:
    return save_hidden_truth(sim_profile, tmp_path / "truth.toml")


async def test_the_wizard_with_virtual_mocap_through_the_service(
    run_dir, monkeypatch, sim_profile, truth, tmp_path
):
    serve_in_thread(monkeypatch)
    mocap = tmp_path / "mocap"
    backend = ServiceBackend(sim_profile, speedup=None, sim_mocap=(str(truth), str(mocap)))
    app = make_app(backend)
    try:
        async with app.run_test(size=(100, 32)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30)
            state = await mocap_wizard(pilot, tmp_path / "session")  # takes written in the service
            result = state.calibration.result
            assert result is not None, state.calibration.message
            assert result.rms_before_mm > 1.0 and result.rms_after_mm < 0.1
            assert result.trusted is True
            assert (tmp_path / "session" / "calibrated.toml").is_file()
    finally:
        backend.close()


async def test_a_faulted_device_refuses_calibrate_through_the_service(
    run_dir, monkeypatch, tmp_path
):
    serve_in_thread(monkeypatch)
    markers = write_markers(tmp_path / "markers.toml", "paper-prototype")
    backend = ServiceBackend("paper-prototype", speedup=None)
    app = make_app(backend)
    try:
        async with app.run_test(size=(100, 32)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30)
            home = backend.home()
            assert home.homed
            assert backend.emergency_stop()
            await pilot.press("f4")
            screen = app.screen
            screen.query_one("#session-dir", Input).value = str(tmp_path / "session")
            screen.query_one("#mocap", Input).value = str(markers)
            await pilot.press("n")
            state = await wait_for(
                pilot, lambda s: s.calibration.stage in ("planned", "error"), timeout=60
            )
            assert state.calibration.stage == "planned", state.calibration.message
            await pilot.press("m")
            state = await wait_for(
                pilot, lambda s: s.calibration.stage == "error" and not s.busy, timeout=60
            )
            message = state.calibration.message
            assert "refused, nothing sent" in message and "M999" in message, message
            assert state.calibration.poses[0].status == "planned"  # nothing moved
            assert backend.device_status().steps == home.steps
    finally:
        backend.close()


async def test_the_camera_through_the_service_takes_pictures_of_the_settled_pose(
    run_dir, monkeypatch, tmp_path
):
    size = (960, 540)
    serve_in_thread(monkeypatch)
    intrinsics = tmp_path / "camera.toml"
    intrinsics.write_text(intrinsics_toml(true_intrinsics(rig_for_size(size))), encoding="utf-8")
    backend = ServiceBackend("paper-simulation", speedup=None)
    app = make_app(backend)
    try:
        async with app.run_test(size=(110, 34)) as pilot:
            await wait_for(pilot, lambda s: s.connected, timeout=30)
            camera = f"sim:{size[0]}x{size[1]}"  # rendered in the service
            state = await camera_first_pose(pilot, tmp_path / "session", camera, intrinsics)
            pose = state.calibration.poses[0]
            assert pose.status == "take ok", pose.detail
    finally:
        backend.close()
    assert (tmp_path / "session" / "takes" / "pose_0001" / "frame_1.jpg").is_file()


@pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux")
@pytest.mark.timeout(300)
def test_the_wizard_on_a_pty_device_through_the_services_process(
    monkeypatch, sim_profile, truth, tmp_path
):
    """The service in a process of its own holds the pty; the sim-device's own virtual
    motion capture writes the takes, named in the take field as an operator would."""
    monkeypatch.setenv("CDPRHOST_STATE", str(tmp_path / "state"))
    mocap = tmp_path / "mocap"
    markers = write_markers(tmp_path / "markers.toml", sim_profile.name)
    args = ("--speedup", "20", "--truth", str(truth), "--mocap-dir", str(mocap))
    with SimDeviceProcess(tmp_path, *args) as dev:
        backend = ServiceBackend(sim_profile)
        try:
            backend.connect(dev.path, 250000)
            calib = backend.calibration
            assert calib is not None
            view = calib.plan(4, 2, str(tmp_path / "session"), str(markers))
            for k, pose in enumerate(view.poses, start=1):
                seen = set(mocap.glob("take-*.csv"))
                settled = calib.move_to(pose)
                assert settled.status == "settled"
                # the newest take (a homing before the first pose settles and writes one too)
                wait_until(lambda s=seen: set(mocap.glob("take-*.csv")) - s, 20, f"take {k}")
                take = max(set(mocap.glob("take-*.csv")) - seen)
                measured = calib.ingest(settled, str(take))
                assert measured.status == "take ok", measured.detail
            result = calib.identify()
            assert result.rms_before_mm > 1.0 and result.rms_after_mm < 0.1
            assert result.trusted is True, result.warnings
            assert result.profile_path.endswith("calibrated.toml")
            assert Path(result.profile_path).is_file()
        finally:
            backend.close()
