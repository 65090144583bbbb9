"""Without the AVR toolchain the AVR half skips, and `sim-device --firmware avr` says how
to install it (one line, exit 2, no traceback)."""

from __future__ import annotations

import shutil

from cdprhost.cli.main import main
from cdprhost.sim import avr_device


def test_a_missing_compiler_names_the_packages(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    hint = avr_device.toolchain_missing()
    assert hint and "apt-get install -y gcc-avr avr-libc simavr libsimavr-dev" in hint


def test_sim_device_without_the_toolchain_is_a_usage_error(monkeypatch, capsys):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert main(["sim-device", "--firmware", "avr"]) == 2
    err = capsys.readouterr().err
    assert "apt-get install" in err and "Traceback" not in err
