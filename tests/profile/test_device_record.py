"""The profile's record of its board: a validated ``[device]`` table, and the sidecar
cdprhost writes after a connect (a profile, shipped or the user's, is never rewritten)."""

from __future__ import annotations

import pytest

from cdprhost.errors import InputError
from cdprhost.profile import (
    DeviceRecord,
    device_record_path,
    load_profile,
    profile_to_toml,
    record_device,
    resolve_profile_path,
)
from cdprhost.profile.loader import SHIPPED_DIR

AVR = DeviceRecord(max_step_rate=10_000, min_segment_s=400e-6, firmware="cdpr-avr 3.0")


@pytest.fixture
def user_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path / "profiles"))
    return tmp_path / "profiles"


def _mine(folder, device_table: str = ""):
    folder.mkdir(parents=True, exist_ok=True)
    text = profile_to_toml(load_profile("paper-prototype")).replace(
        'name = "paper-prototype"', 'name = "mine"'
    )
    path = folder / "mine.toml"
    path.write_text("# my notes\n" + text + device_table)
    return path


def test_a_hand_written_device_table_is_read_and_checked(user_dir):
    _mine(user_dir, "\n[device]\nmax_step_rate = 12500\nmin_segment_s = 0.0004\n")
    assert load_profile("mine").device == DeviceRecord(max_step_rate=12_500, min_segment_s=4e-4)
    assert load_profile("paper-prototype").device is None
    _mine(user_dir, "\n[device]\nmax_step_rate = 0\nspeed = 3\n")
    with pytest.raises(InputError) as err:
        load_profile("mine")
    text = str(err.value)
    assert "mine.toml" in text and "device.max_step_rate" in text and "device.speed" in text


def test_a_shipped_profile_s_record_goes_to_the_user_folder(user_dir):
    shipped = SHIPPED_DIR / "paper-prototype.toml"
    before = shipped.read_bytes()
    written = record_device("paper-prototype", AVR)
    assert written == user_dir / "paper-prototype.device.toml"
    assert shipped.read_bytes() == before
    assert load_profile("paper-prototype").device == AVR
    # the same limits again: nothing written
    assert record_device("paper-prototype", AVR.model_copy(update={"firmware": "x"})) is None


def test_a_user_profile_s_record_is_a_sidecar_beside_it_and_takes_precedence(user_dir, tmp_path):
    path = _mine(tmp_path / "elsewhere", "\n[device]\nmax_step_rate = 5000\n")
    before = path.read_text()
    assert record_device(path, AVR) == tmp_path / "elsewhere" / "mine.device.toml"
    assert path.read_text() == before  # comments and all
    assert load_profile(path).device == AVR
    assert device_record_path(resolve_profile_path(path)).is_file()


def test_a_broken_sidecar_names_its_file(user_dir):
    user_dir.mkdir(parents=True)
    bad = user_dir / "paper-prototype.device.toml"
    bad.write_text("[device]\nmax_step_rate = -3\n")
    with pytest.raises(InputError, match=r"paper-prototype\.device\.toml.*\n.*max_step_rate"):
        load_profile("paper-prototype")
    bad.write_text("max_step_rate = 3\n")
    with pytest.raises(InputError, match="one \\[device\\] table"):
        load_profile("paper-prototype")
