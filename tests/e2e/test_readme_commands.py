"""Every command shown in README.md and examples/README.md runs as written.

The commands are read from the documents (each line of a ```bash block, each part of a
line joined by ``&&``, and every inline `cdprhost ...` span), in order, and run by bash
in a scratch folder holding a copy of ``examples/`` (with HOME and the XDG folders
inside it, so nothing of the user's is read or written). Only what ``SKIP`` names is
not run, each for its stated reason; ``EXIT`` names the commands the documents say
end with another status. Speed: the simulated devices run as fast as the host can
(``sim-device``'s documented 5x becomes ``FAST``); the embedded print already does.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = (ROOT / "README.md", ROOT / "examples" / "README.md")
FAST = "1000"

#: command prefix -> why it is not run here
SKIP = {
    "python3 -m venv": "the install: this test runs in the installed package",
    ". .venv/bin/activate": "the install: this test runs in the installed package",
    "pip install": "the install: this test runs in the installed package",
    "python -m pytest": "the whole suite: this test is part of it",
    "python bench/": "benchmarks: minutes each, measured by hand and reported as ratios",
    "cdprhost tui": "the interactive terminal UI (its own tests drive it)",
    "cdprhost serve": "a server that runs until stopped (its own tests drive it)",
    "cdprhost calibrate camera --camera 0": "needs a real camera",
    "cdprhost calibrate wizard --profile paper-simulation --port /dev/ttyACM0": "needs a real "
    "machine and camera",
    "cdprhost sim-device": "a device that runs until stopped: the bash block that shows "
    "it with '&' is run, in the background",
}
#: command prefix -> the exit status the documents give it, and why
EXIT = {
    "cdprhost calibrate identify demo-session --profile paper-simulation": (
        1,
        "the README shows the refusal: the demo's hidden effect makes the check poses disagree",
    ),
    "cdprhost print examples/example.gcode --profile paper-prototype --port /dev/pts/3 --resume": (
        2,
        "after a completed print there is no resume point: the README says exit 2",
    ),
}


def _commands(text: str) -> list[str]:
    """Commands in document order: bash block lines (comments dropped) and inline spans."""
    found: list[tuple[int, str]] = []
    for block in re.finditer(r"```bash\n(.*?)```", text, flags=re.S):
        offset = block.start(1)
        for line in block.group(1).splitlines():
            code = re.sub(r"\s+#.*$", "", line).strip()
            if code and not code.startswith("#"):
                found.append((offset, code))
            offset += len(line) + 1
    prose = re.sub(r"```.*?```", lambda m: " " * len(m.group(0)), text, flags=re.S)
    for span in re.finditer(r"`(cdprhost [^`]+)`", prose):
        found.append((span.start(), " ".join(span.group(1).split())))
    return [c for _, c in sorted(found, key=lambda pair: pair[0])]


def _parts(command: str) -> list[str]:
    return [p.strip() for p in command.split("&&")]


def _skipped(part: str) -> str | None:
    if part.endswith("&"):
        return None
    return next((why for prefix, why in SKIP.items() if part.startswith(prefix)), None)


def _expected(part: str) -> int:
    return next((code for prefix, (code, _) in EXIT.items() if part.startswith(prefix)), 0)


def test_the_documents_show_commands_and_every_exception_is_used():
    parts = [p for doc in DOCS for c in _commands(doc.read_text()) for p in _parts(c)]
    assert sum(p.startswith("cdprhost ") for p in parts) >= 20
    for prefix in EXIT:
        assert any(p.startswith(prefix) for p in parts), (
            f"EXIT entry not in the documents: {prefix}"
        )
    for part in parts:  # a syntax summary ("[--port DEV]") would be a command we cannot run
        if not _skipped(part):
            assert "[" not in part and "|" not in part, part


@pytest.mark.slow
def test_every_command_in_the_readmes_runs_as_written(tmp_path):
    work = tmp_path / "clone"
    shutil.copytree(ROOT / "examples", work / "examples")
    env = {
        **os.environ,
        "HOME": str(tmp_path / "home"),
        "XDG_CONFIG_HOME": str(tmp_path / "home" / ".config"),
        "XDG_STATE_HOME": str(tmp_path / "home" / ".local" / "state"),
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
    }
    env.pop("CDPRHOST_PROFILES", None)
    background: list[subprocess.Popen[str]] = []
    pty: str | None = None
    ran, seen = [], set()
    try:
        for doc in DOCS:
            for command in _commands(doc.read_text()):
                for part in _parts(command):
                    if _skipped(part) or part in seen:
                        continue
                    seen.add(part)
                    if part.endswith("&"):  # sim-device in the background: its pty path
                        line = re.sub(r"--speedup \S+", f"--speedup {FAST}", part[:-1])
                        proc = subprocess.Popen(
                            ["bash", "-c", f"exec {line}"],
                            cwd=work,
                            env=env,
                            stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE,
                            text=True,
                        )
                        background.append(proc)
                        assert proc.stdout is not None
                        pty = proc.stdout.readline().strip()
                        assert pty.startswith("/dev/"), f"{part}: first line {pty!r}"
                        ran.append(part)
                        continue
                    line = part.replace("/dev/pts/3", pty) if pty else part
                    run = subprocess.run(
                        ["bash", "-c", line],
                        cwd=work,
                        env=env,
                        capture_output=True,
                        text=True,
                        timeout=240,
                        check=False,
                    )
                    want = _expected(part)
                    assert run.returncode == want, (
                        f"{doc.name}: {part}\nexit {run.returncode}, expected {want}\n"
                        f"{run.stdout[-1500:]}\n{run.stderr[-1500:]}"
                    )
                    assert "Traceback" not in run.stderr, run.stderr[-3000:]
                    ran.append(part)
    finally:
        for proc in background:
            proc.send_signal(signal.SIGTERM)
            proc.communicate(timeout=30)
    assert len(ran) >= 18
    # what the documents promise the commands leave behind
    for name in ("my-machine.toml", "printer.cfg", "targets.csv", "report.json", "job.json"):
        assert (work / name).is_file(), name
    for name in ("demo-session/hidden-truth.toml", "augmented.toml", "calibrated.toml", "gap.png"):
        assert (work / name).is_file(), name
    assert (work / "my-session" / "calibrated.toml").is_file()
    assert background and all(p.returncode == 0 for p in background)
