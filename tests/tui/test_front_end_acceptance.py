"""Issue 32's front-end acceptance runs, fast: ``bench/front_end_acceptance.py`` drives a real
``cdprhost tui`` on a pseudo-terminal (120x40) that prints a small part on a pty sim-device at
20x through the printer service. The scenarios test_service_pty.py does not cover:

- busy loops at the TUI's priority for the whole print;
- a second front end (``cdprhost print --attach``) watching the print the TUI started: both
  see it completed, at the same last layer (the TUI's screen shows DONE and n/n).

(The TUI killed or stopped mid-print: test_service_pty.py. The 1x runs on the cup: the
bench itself, ~15 min.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.e2e.processes import square_part

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.timeout(900),
]
ROOT = Path(__file__).resolve().parents[2]


def _bench(tmp_path: Path, *args: str) -> dict:
    gcode = square_part(tmp_path / "part.gcode", layers=6)
    out = tmp_path / "outcomes.json"
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "bench" / "front_end_acceptance.py"),
            "--gcode",
            str(gcode),
            "--speedup",
            "20",
            "--timeout",
            "400",
            "--json",
            str(out),
            *args,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=850,
        check=False,
    )
    assert out.exists(), run.stdout + run.stderr
    outcomes = json.loads(out.read_text())
    assert run.returncode == 0, run.stdout + run.stderr
    return outcomes


def test_a_tui_prints_to_the_end_while_busy_loops_run_at_its_priority(tmp_path):
    o = _bench(tmp_path, "--only", "busy", "--busy", "2")["busy"]
    assert o["completed"] and o["end_state"] == "done", o
    assert o["segments"] > 0
    assert not o["watchdog"] and o["underruns"] == 0, o


def test_a_tui_and_a_watcher_see_the_same_print_end(tmp_path):
    o = _bench(tmp_path, "--only", "watch", "--busy", "0")["watch"]
    assert o["completed"] and not o["error"], o
    assert o["watcher"].startswith("status completed, last layer 6,"), o
    assert o["screen"] == "DONE 6/6", o
    assert not o["watchdog"], o
