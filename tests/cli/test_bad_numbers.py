"""Absurd numbers in options and profiles get one clear line and exit 2, never a traceback."""

from __future__ import annotations

import pytest

from cdprhost.cli.main import main
from cdprhost.cli.progress_view import ProgressView
from cdprhost.job.state import Failure, Planned


@pytest.mark.parametrize(
    "argv, where",
    [
        (["print", "{g}", "-p", "paper-prototype", "--baud", "1e24"], "--baud"),
        (["print", "{g}", "-p", "paper-prototype", "--baud", "1" + "0" * 30], "--baud"),
        (["print", "{g}", "-p", "paper-prototype", "--speedup", "nan"], "--speedup"),
        (["print", "{g}", "-p", "paper-prototype", "--speedup", "1e308"], "--speedup"),
        (["print", "{g}", "-p", "paper-prototype", "--resume-from-layer", "0"], "--resume-from"),
        (
            ["print", "{g}", "-p", "paper-prototype", "--resume", "--resume-from-layer", "2"],
            "--resume",
        ),
        (["print", "{g}", "-p", "paper-prototype", "--sim-faults", "drop=3"], "--sim-faults"),
        # every command that opens a device takes the same --port/--baud
        (["tui", "--baud", "-5"], "--baud"),
        (["serve", "-p", "paper-prototype", "--baud", "0"], "--baud"),
        (["autotune", "M303 E0 S210 C8", "-p", "paper-prototype", "--baud", "-1"], "--baud"),
        (["calibrate", "wizard", "-p", "paper-prototype", "--baud", "7"], "--baud"),
        (["print", "{g}", "-p", "paper-prototype", "--port", " "], "--port"),
        (["sim-device", "--speedup", "nan"], "--speedup"),
        (["sim-device", "--speedup", "-1"], "--speedup"),
        (["sim-device", "--ring-entries", "96"], "--ring-entries"),  # not a power of two
        (["sim-device", "--ring-entries", "256"], "--ring-entries"),
        (["sim-device", "--firmware", "avr", "--ring-entries", "64"], "--ring-entries"),
        (["sim-device", "--total-step-rate", "5000"], "--total-step-rate"),  # < one axis's
        (["sim-device", "--firmware", "avr", "--total-step-rate", "90000"], "--total-step-rate"),
        (
            [
                "calibrate",
                "identify",
                "s",
                "-p",
                "paper-prototype",
                "--out",
                "o",
                "--noise-floor",
                "1e308",
            ],
            "--noise-floor",
        ),
        (
            [
                "calibrate",
                "identify",
                "s",
                "-p",
                "paper-prototype",
                "--out",
                "o",
                "--noise-floor",
                "nan",
            ],
            "--noise-floor",
        ),
    ],
)
def test_absurd_options(argv, where, tmp_path, capsys):
    g = tmp_path / "part.gcode"
    g.write_text("G28\nG1 X1 Y1 Z1 F600\n")
    with pytest.raises(SystemExit) as exc_or_code:
        code = main([a.format(g=g) for a in argv])
        raise SystemExit(code)
    err = capsys.readouterr().err
    assert exc_or_code.value.code == 2 and where in err and "Traceback" not in err


@pytest.mark.parametrize(
    "key, value", [("timeout_s", 1e308), ("timeout_s", float("nan")), ("baud", 10**10)]
)
def test_absurd_serial_settings_in_a_profile(key, value, tmp_path, capsys):
    import tomli_w

    from cdprhost.profile import load_profile

    data = load_profile("paper-prototype").model_dump(mode="json", exclude_none=True)
    data["serial"][key] = value
    path = tmp_path / "p.toml"
    path.write_text(tomli_w.dumps(data))
    g = tmp_path / "part.gcode"
    g.write_text("G28\n")
    assert main(["print", str(g), "-p", str(path)]) == 2
    err = capsys.readouterr().err
    assert "serial" in err and "Traceback" not in err


def test_console_and_result_agree_on_the_layer(capsys):
    import io

    out = io.StringIO()
    view = ProgressView(stream=out)
    view.update(Planned(10, 100, 60.0, 1.0))
    view.update(Failure("boom", 120, 0, (1.0, 2.0, 3.0), "/x.resume.json"))  # 0-based layer 0
    text = out.getvalue()
    assert "line 120, layer 1" in text and "layer 0" not in text and "/-1" not in text
