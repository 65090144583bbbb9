"""PID autotune end to end: M303 parsed on the G-code path, run by the device model,
the gains stored in the profile and sent to the device at the next connect."""

from __future__ import annotations

import pytest

from cdprhost.cli.commands.autotune import parse_m303
from cdprhost.cli.main import main
from cdprhost.errors import CdprError
from cdprhost.machine.commands import device_messages
from cdprhost.machine.operations import Machine
from cdprhost.profile import load_profile
from cdprhost.profile.loader import SHIPPED_DIR, profile_from_dict
from cdprhost.profile.models import PidGains, with_pid
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.messages import Autotune


def test_m303_is_a_command_on_the_gcode_path():
    tune = parse_m303("M303 E0 S210 C8")
    assert (tune.heater, tune.target_c, tune.cycles) == ("hotend", 210.0, 8)
    bed = parse_m303("M303 E-1 S60")
    assert (bed.heater, bed.target_c, bed.cycles) == ("bed", 60.0, 5)
    msgs = device_messages(tune, model=None, home_mm=None, clock_hz=100_000)  # type: ignore[arg-type]
    assert msgs == [Autotune(0, 2100, 8)]
    with pytest.raises(CdprError, match="E must be 0"):
        parse_m303("M303 E1 S210")
    with pytest.raises(CdprError, match="3..20 cycles"):
        parse_m303("M303 E0 S210 C40")


def test_profiles_without_gains_still_load_and_gains_round_trip(tmp_path):
    profile = load_profile("paper-simulation")
    assert profile.heaters.hotend_pid is None and profile.heaters.bed_pid is None
    tuned = with_pid(profile, "bed", PidGains(kp=70.0, ki=1.5, kd=400.0))
    again = profile_from_dict(tuned.model_dump(mode="json", exclude_none=True))
    assert again.heaters.bed_pid == PidGains(kp=70.0, ki=1.5, kd=400.0)
    assert again.heaters.bed_pid.wire() == (70_000, 1_500, 400_000)


def test_autotune_command_stores_gains_that_the_next_connect_sends(tmp_path, capsys):
    path = tmp_path / "machine.toml"
    path.write_text((SHIPPED_DIR / "paper-simulation.toml").read_text())
    assert main(["autotune", "M303 E0 S210 C4", "--profile", str(path), "--save", "-"]) == 0
    out = capsys.readouterr().out
    assert "M301 P" in out and "saved to" in out
    gains = load_profile(str(path)).heaters.hotend_pid
    assert gains is not None and gains.kp > 0 and gains.ki > 0 and gains.kd > 0
    link = open_embedded()
    try:
        Machine(link, load_profile(str(path)))
        link.request_status()
        pid = link.device.machine.heaters[0].pid
        assert pid is not None and pid.gains.kp == pytest.approx(gains.kp, abs=1e-3)
    finally:
        link.close()
