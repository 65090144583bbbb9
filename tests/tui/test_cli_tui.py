"""`cdprhost tui`: arguments, errors, and the app it builds (not run in a terminal here)."""

from __future__ import annotations

import pytest

from cdprhost.cli.main import main
from cdprhost.tui.app import CdprApp
from cdprhost.tui.control.backend import EMBEDDED


@pytest.fixture
def captured(monkeypatch):
    apps: list[CdprApp] = []

    def fake_run(self, *args, **kwargs):
        apps.append(self)
        return 0

    monkeypatch.setattr(CdprApp, "run", fake_run)
    return apps


def test_defaults_open_the_embedded_device_with_paper_prototype(captured):
    assert main(["tui"]) == 0
    app = captured[0]
    assert app.backend.profile_name == "paper-prototype"
    assert app._port == EMBEDDED and app._baud == 250000
    assert app.DEFAULT_MODE == "print"


def test_port_profile_and_virtual_mocap_options(captured, tmp_path):
    assert (
        main(["tui", "--profile", "paper-simulation", "--port", "loop://", "--baud", "115200"]) == 0
    )
    app = captured[-1]
    assert (
        app.backend.profile_name == "paper-simulation"
        and app._port == "loop://"
        and app._baud == 115200
    )
    mocap = ["--sim-truth", "paper-simulation", "--sim-mocap-dir", str(tmp_path / "mocap")]
    assert main(["tui", *mocap]) == 0  # the virtual motion capture watches the service's device
    assert captured[-1].backend.sim_mocap == ("paper-simulation", str(tmp_path / "mocap"))
    assert main(["tui", "--in-process", *mocap]) == 0  # ... or the device in this process
    assert captured[-1].backend.sim_options["observer"] is not None
    assert main(["tui", "--sim-truth", "no-such-truth", "--sim-mocap-dir", "x"]) == 2


def test_a_file_to_open_on_start(captured, tmp_path, capsys):
    part = tmp_path / "part.gcode"
    part.write_text("G28\n")
    assert main(["tui", str(part)]) == 0
    assert captured[-1]._open_file == str(part)
    assert main(["tui", str(tmp_path / "missing.gcode")]) == 2
    assert "missing.gcode" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["tui", "--profile", "no-such-profile"], "no-such-profile"),
        (["tui", "--sim-truth", "paper-simulation"], "--sim-truth and --sim-mocap-dir go together"),
        (
            ["tui", "--port", "loop://", "--sim-truth", "paper-simulation", "--sim-mocap-dir", "x"],
            "embedded",
        ),
    ],
)
def test_bad_input_exits_2_with_a_message(captured, capsys, argv, message):
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert captured == []
