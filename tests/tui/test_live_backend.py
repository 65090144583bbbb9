"""The UI on the real layers: embedded simulated device, preflight, wizard with virtual mocap, diagnosis."""

from __future__ import annotations

import math

import numpy as np
import pytest
from textual.widgets import DataTable, Input

from cdprhost.calibration.commanding import commanded_path
from cdprhost.diagnosis.workflow import FAST
from cdprhost.effects.base import MotionContext
from cdprhost.sim.scenarios import hidden_truth, measurement_tour, session_times
from cdprhost.sim.synthetic_session import write_synthetic_session
from cdprhost.sim.virtual_mocap import make_observer
from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.live import LiveBackend
from cdprhost.tui.control.live_diagnosis import diagnosis_view, parameter_rows
from firmware_protocol.device.thermal_plant import HOTEND_PLANT
from firmware_protocol.messages import PROTOCOL_MAJOR

from .conftest import make_app, shown, wait_for
from .wizard_steps import mocap_wizard, save_hidden_truth


@pytest.fixture
def live():
    backend = LiveBackend("paper-prototype", speedup=None)
    yield backend
    backend.close()


def test_embedded_device_home_jog_heaters(live):
    rows = dict(live.connect(EMBEDDED, 250000))
    assert rows["firmware"].startswith("cdpr-sim") and rows["protocol"].startswith(
        f"{PROTOCOL_MAJOR}."
    )
    status = live.device_status()
    assert not status.homed and status.position is None  # position unknown until homed
    with pytest.raises(Exception, match="not homed"):
        live.jog_to((0.0, 0.0, 200.0))
    status = live.home()
    home = live.model.home_point(np.asarray(live.profile.drive.home_mm))
    assert status.homed and np.allclose(status.position, home, atol=0.01)
    target = (12.0, -7.5, 240.0)
    status = live.jog_to(target)
    assert np.allclose(status.position, target, atol=0.01)  # steps are absolute: no drift
    expected = live.model.steps(live.model.ik(np.array([target])))[0]
    assert status.steps[:3] == tuple(int(v) for v in expected)
    status = live.set_heaters(205.0, 60.0)
    assert status.hotend_target == 205.0 and status.bed_target == 60.0
    assert not live.motors_off().motors_on
    health = live.link_health()
    assert health.retransmits == 0 and health.bad_frames == 0


def test_preflight_view_on_real_preflight(live, tmp_path):
    good = tmp_path / "good.gcode"
    good.write_text("G28\nM104 S200\nM109 S200\nG1 Z0.3 F600\nG1 X10 Y0 E1 F1200\nG1 X10 Y10 E2\n")
    view = live.preflight(str(good))
    assert view.ok and view.moves >= 3 and view.violations == ()
    bad = tmp_path / "bad.gcode"
    bad.write_text("G28\nM104 S200\nM109 S200\nG1 Z0.3 F600\nG1 X400 Y0 E1 F1200\n")
    view = live.preflight(str(bad))
    assert not view.ok and view.violations[0].line == 5


def test_diagnosis_view_from_report():
    report = {
        "verdict": "named",
        "effect": "drift",
        "effects": ["drift"],
        "where": "cable 2 grows with time",
        "candidates": [
            {"name": "drift", "p_value": 1e-12, "delta_bic": -80.0, "heldout_rms_mm": 0.09},
            {"name": "backlash", "p_value": float("nan"), "delta_bic": None, "heldout_rms_mm": 0.2},
        ],
        "heldout_rms_before_mm": 0.3,
        "heldout_rms_after_mm": 0.09,
        "noise_floor_mm": 0.088,
        "poses": {"heldout_before_mm": [0.2, 0.4], "heldout_after_mm": [0.08, 0.1]},
        "parameters": {
            "drift": {
                "table": {"rho": [1e-4, -2e-4, 3e-4], "rho_stderr": [1e-5] * 3},
                "ci95": {"rho": [[0.8e-4, 1.2e-4], [-2.2e-4, -1.8e-4], [2.8e-4, 3.2e-4]]},
            }
        },
    }
    view = diagnosis_view(report)
    assert view.verdict == "named" and view.effect == "drift"
    assert view.candidates[1].p_value is None and view.candidates[1].delta_bic is None
    assert view.per_pose_before_mm == (0.2, 0.4)
    rows = dict(parameter_rows(report))
    assert list(rows) == ["drift.rho"] and rows["drift.rho"].startswith(
        "[0.0001, -0.0002, 0.0003] (95% [8e-05"
    )


def write_hidden_session(directory, model, effect, seed):
    rng = np.random.default_rng(seed)
    truth = hidden_truth(model, rng, effect)
    poses = measurement_tour(model, 40, rng)
    t_s = session_times(40, rng)
    s_cmd, dirs = commanded_path(model, poses)
    actual = truth.fk(s_cmd, MotionContext(t_s=t_s, directions=dirs))
    write_synthetic_session(
        directory,
        actual,
        poses,
        s_cmd,
        t_s,
        dirs.astype(int),
        "paper-simulation",
        noise_mm=0.05,
        seed=seed + 1,
    )


async def test_diagnose_screen_on_a_session_with_a_hidden_effect(tmp_path):
    backend = LiveBackend("paper-simulation", speedup=None, diagnosis_settings=FAST)
    write_hidden_session(tmp_path / "session", backend.model, "drive_scale", seed=3)
    app = make_app(backend, connect_on_start=False)
    async with app.run_test(size=(100, 32)) as pilot:
        await pilot.press("f5", "e")
        app.screen.query_one("#diag-session", Input).value = str(tmp_path / "session")
        await pilot.press("enter")
        state = await wait_for(
            pilot, lambda s: s.diagnose.result is not None or s.diagnose.error, timeout=60
        )
        assert state.diagnose.error == ""
        d = state.diagnose.result
        assert d.verdict == "named" and d.effect == "drive_scale"
        assert d.heldout_rms_after_mm < d.heldout_rms_before_mm
        assert len(d.per_pose_before_mm) == 40
        text = await shown(pilot)
        assert "verdict named  effect drive_scale" in text and "drive_scale.eps" in text


async def test_calibration_wizard_screen_with_virtual_mocap(sim_profile, tmp_path):
    observer = make_observer(
        save_hidden_truth(sim_profile, tmp_path / "truth.toml"), tmp_path / "mocap"
    )
    backend = LiveBackend(sim_profile, speedup=None, sim_options={"observer": observer})
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        state = await mocap_wizard(pilot, tmp_path / "session")
        result = state.calibration.result
        assert result is not None, state.calibration.message
        assert result.rms_before_mm > 1.0 and result.rms_after_mm < 0.1
        assert result.check_after_mm < 0.5 < result.check_before_mm  # the check poses confirm it
        assert app.screen.query_one("#parameters", DataTable).row_count == 12
        assert (tmp_path / "session" / "calibrated.toml").is_file()
        assert result.profile_path.endswith("calibrated.toml")
        assert result.trusted is True  # the trust gate's verdict, shown
        assert "trust gate: trusted" in await shown(pilot)


async def test_a_new_calibration_session_needs_its_markers_first(tmp_path):
    """On a device without virtual motion capture, a new session takes its [mocap] table from
    a TOML file (as the CLI's --mocap-config); without one nothing is written."""
    import tomli_w

    from cdprhost.sim.virtual_mocap import mocap_config

    markers = tmp_path / "markers.toml"
    table = mocap_config("paper-prototype").mocap.model_dump(mode="json", exclude_none=True)
    session = {"session": {"profile": "paper-prototype"}, "mocap": table}
    markers.write_text(tomli_w.dumps(session), encoding="utf-8")
    backend = LiveBackend("paper-prototype", speedup=None)
    app = make_app(backend)
    async with app.run_test(size=(100, 32)) as pilot:
        await wait_for(pilot, lambda s: s.connected, timeout=20)
        await pilot.press("f4")
        screen = app.screen
        screen.query_one("#session-dir", Input).value = str(tmp_path / "session")
        await pilot.press("n")
        state = await wait_for(pilot, lambda s: s.calibration.stage in ("planned", "error"), 60)
        assert state.calibration.stage == "error"
        assert "needs the motion-capture configuration" in state.calibration.message
        assert not (tmp_path / "session").exists()  # no plan.csv before the check
        screen.query_one("#mocap", Input).value = str(tmp_path / "missing.toml")
        await pilot.press("n")
        state = await wait_for(pilot, lambda s: not s.busy and s.calibration.stage == "error", 60)
        assert "missing.toml" in state.calibration.message
        assert not (tmp_path / "session").exists()
        screen.query_one("#mocap", Input).value = str(markers)
        await pilot.press("n")
        state = await wait_for(pilot, lambda s: s.calibration.stage in ("planned", "error"), 60)
        assert state.calibration.stage == "planned", state.calibration.message
        assert (tmp_path / "session" / "session.toml").is_file()
        assert (tmp_path / "session" / "plan.csv").is_file()


def test_idle_status_keeps_the_embedded_device_clock_running():
    backend = LiveBackend("paper-prototype", speedup=None, idle_pump_s=2.0)
    try:
        backend.connect(EMBEDDED, 250000)
        backend.set_heaters(200.0, 0.0)
        # 2 s of device time per status; the hotend answers after its dead time (the thermistor's
        # noise until then), so the statuses inside it are passed over
        skip = math.ceil(HOTEND_PLANT.dead_time_s / 2.0) + 1
        temps = [backend.device_status().hotend for _ in range(skip + 4)][skip:]
    finally:
        backend.close()
    assert all(b > a for a, b in zip(temps, temps[1:])), temps  # then it heats
