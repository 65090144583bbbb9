"""`cdprhost diagnose --write`: the improved profile written atomically, only when the
diagnosis improved it, never over a shipped profile (said first)."""

from __future__ import annotations

import shutil

import pytest

from cdprhost.cli.main import main
from cdprhost.profile import load_profile
from cdprhost.profile.loader import SHIPPED_DIR
from tests.diagnosis.sessions import write_hidden_session


@pytest.fixture(scope="module")
def named_session(tmp_path_factory, sim_model):
    session = tmp_path_factory.mktemp("write") / "session"
    write_hidden_session(session, sim_model, "drive_scale", 31)
    return session


def test_write_puts_the_named_effect_into_the_profile_file(named_session, tmp_path, capsys):
    profile = tmp_path / "mine.toml"
    shutil.copy(SHIPPED_DIR / "paper-simulation.toml", profile)
    assert not load_profile(profile).effects
    rc = main(["diagnose", str(named_session), "--profile", str(profile), "--write", "-q"])
    assert rc == 0
    assert f"wrote the improved profile to {profile}" in capsys.readouterr().out
    written = load_profile(profile)
    assert "drive_scale" in written.effects
    assert not list(tmp_path.glob("*.tmp*"))  # the atomic writer left nothing behind


def test_a_shipped_profile_is_never_rewritten_the_user_copy_is(
    named_session, tmp_path, monkeypatch, capsys
):
    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path / "profiles"))
    shipped = (SHIPPED_DIR / "paper-simulation.toml").read_bytes()
    rc = main(["diagnose", str(named_session), "--profile", "paper-simulation", "--write", "-q"])
    assert rc == 0
    out = capsys.readouterr()
    copy = tmp_path / "profiles" / "paper-simulation.toml"
    assert "is a shipped profile and is not rewritten" in out.err
    assert f"wrote the improved profile to {copy}" in out.out
    assert (SHIPPED_DIR / "paper-simulation.toml").read_bytes() == shipped
    assert "drive_scale" in load_profile("paper-simulation").effects


def test_nothing_is_written_when_the_diagnosis_names_no_effect(tmp_path, sim_model, capsys):
    session = tmp_path / "session"
    write_hidden_session(session, sim_model, None, 33)
    profile = tmp_path / "mine.toml"
    shutil.copy(SHIPPED_DIR / "paper-simulation.toml", profile)
    before = profile.read_bytes()
    rc = main(["diagnose", str(session), "--profile", str(profile), "--write", "-q"])
    assert rc == 0
    assert "profile not written: the verdict is 'none'" in capsys.readouterr().err
    assert profile.read_bytes() == before
