"""Fast start: each command imports only what it uses (cdprhost/cli/main.py)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from cdprhost.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
# Stacks the print path must never load: they cost seconds before the first byte moves.
NOT_ON_PRINT_PATH = (
    "cdprhost.calibration",
    "cdprhost.diagnosis",
    "cdprhost.tui",
    "cdprhost.sim.virtual_mocap",
    "matplotlib",
    "textual",
    "scipy.optimize",
    "scipy.stats",
)


def loaded_modules(*argv: str) -> set[str]:
    """Run the CLI in a fresh interpreter; the names in sys.modules when it returns."""
    code = (
        "import json, sys\n"
        "from cdprhost.cli.main import main\n"
        "try:\n"
        f"    main({list(argv)!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        "sys.stdout = sys.__stdout__\n"
        "print('\\n@@' + json.dumps(sorted(sys.modules)))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    tail = out.stdout.rsplit("\n@@", 1)
    assert len(tail) == 2, out.stderr[-2000:]
    return set(json.loads(tail[1]))


def test_every_command_module_registers_what_the_table_says():
    by_module: dict[str, set[str]] = {}
    for name, (module, _) in cli_main.COMMANDS.items():
        by_module.setdefault(module, set()).add(name)
    files = {p.stem for p in (ROOT / "cdprhost/cli/commands").glob("*.py") if p.stem != "__init__"}
    assert files == set(by_module), "every command module is in COMMANDS, and only those"
    for module, names in by_module.items():
        sub = argparse.ArgumentParser().add_subparsers()
        cli_main.load_command(module).register(sub)
        assert set(sub.choices) == names, module


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_version_and_help_import_no_numeric_stack(argv):
    mods = loaded_modules(*argv)
    assert "numpy" not in mods
    assert not any(m.startswith("cdprhost.cli.commands.") for m in mods)


def test_check_and_print_paths_skip_calibration_diagnosis_plotting_and_tui(tmp_path):
    gcode = tmp_path / "cube.gcode"
    gcode.write_text("G28\nG1 Z0.3 F1200\nG1 X5 Y0 E0.5 F1200\nG1 X5 Y5 E1.0\n")
    for argv in (
        ["check", str(gcode), "--profile", "paper-prototype"],
        ["print", str(gcode), "--profile", "paper-prototype", "--yes"],
    ):
        mods = loaded_modules(*argv)
        assert "cdprhost.gcode" in mods, argv  # the command really ran
        bad = sorted(m for m in mods if m.startswith(NOT_ON_PRINT_PATH))
        assert not bad, f"{argv[0]} imported {bad}"
