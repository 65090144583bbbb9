"""CPU of the terminal UI while it prints at 1x, against the CLI printing the same file.

Run: python bench/tui_cpu.py [--seconds 60] [--size 200x60] [--file PATH] [--idle-only]

Two ``cdprhost sim-device --speedup 1`` processes on pseudo-terminals stand in for the
machine. The UI (``cdprhost tui --port PTY FILE``) runs in a pseudo-terminal of the given
size, drawing as it would for an operator (its output is read and thrown away); the keys
``s`` and ``y`` start the print. Its process CPU time (every thread: screen, job runner,
link) is read from /proc over ``--seconds`` of printing, after the same time connected and
idle, once the machine moves (``--warmup`` after the start: the fixture heats first). The
baseline, measured in the same run: ``cdprhost print --port PTY FILE`` (the same
job runner and link, no screen) over the same time. Reported: CPU as % of one core, and the
UI's printing cost as a ratio of the CLI's.

Target (issue 15): the UI process at <= 5 % of one core while printing at 1x; (issue 32)
under 2 % connected and idle. ``--idle-only`` measures only that, ``--seconds`` long, and
the printer service's CPU beside it (the UI is its client: the link and the device's status
polls run there; ``--in-process``: the UI drives the device itself, no service). The run
has a state and a service folder of its own.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_inputs import gcode_fixture

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.tui.pty_terminal import PtyTerminal, tui_argv  # noqa: E402

TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def main_thread_seconds(pid: int) -> float:
    """CPU time of the process's main thread (the UI's event loop: screen and drawing)."""
    fields = Path(f"/proc/{pid}/task/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def sim_device() -> tuple[subprocess.Popen[str], str]:
    dev = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", "--speedup", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert dev.stdout is not None
    return dev, dev.stdout.readline().strip()


def shown(ui: PtyTerminal, text: str, timeout: float) -> None:
    why = ui.wait_for(text, timeout)
    if why:
        raise SystemExit(why)


def measure(pid: int, seconds: float, windows: list[float] | None = None) -> float:
    """% of one core over ``seconds``; ``windows`` collects it per 10 s."""
    c0, t0 = cpu_seconds(pid), time.monotonic()
    c, t = c0, t0
    while time.monotonic() - t0 < seconds:
        time.sleep(min(10.0, seconds - (time.monotonic() - t0)))
        c1, t1 = cpu_seconds(pid), time.monotonic()
        if windows is not None:
            windows.append(100.0 * (c1 - c) / (t1 - t))
        c, t = c1, t1
    return 100.0 * (cpu_seconds(pid) - c0) / (time.monotonic() - t0)


def service_pid(port: str) -> int | None:
    """The printer service of ``port`` in this run's folder (None: none runs)."""
    from cdprhost.service.paths import files_for_port

    pid = files_for_port(port).read_pid()
    return pid if pid and Path(f"/proc/{pid}").exists() else None


def stop_service(port: str) -> None:
    pid = service_pid(port)
    if pid is not None:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)


def idle_only(ui_pid: int, port: str, seconds: float, cols: int, rows: int) -> None:
    """The UI connected and idle, and its printer service meanwhile."""
    service = service_pid(port)
    s0 = cpu_seconds(service) if service else 0.0
    t0 = time.monotonic()
    windows: list[float] = []
    idle = measure(ui_pid, seconds, windows)
    served = 100.0 * (cpu_seconds(service) - s0) / (time.monotonic() - t0) if service else None
    print(f"terminal {cols}x{rows}, {seconds:g} s")
    print(f"UI connected, idle:        {idle:5.1f} % of one core (target < 2 %)")
    print("  per 10 s:                " + " ".join(f"{w:.1f}" for w in windows))
    if served is not None:
        print(f"its printer service:       {served:5.1f} % of one core")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--size", default="200x60")
    ap.add_argument(
        "--file", type=Path, help="default: the team's fixture, else examples/example.gcode"
    )
    ap.add_argument(
        "--warmup",
        type=float,
        default=75.0,
        help="seconds after the start before measuring (the fixture heats first: at 1x about a minute)",
    )
    ap.add_argument("--idle-only", action="store_true", help="only the UI connected and idle")
    ap.add_argument(
        "--in-process", action="store_true", help="the UI drives the device (no printer service)"
    )
    args = ap.parse_args()
    args.file = gcode_fixture(args.file)
    cols, rows = (int(v) for v in args.size.split("x"))
    cdprhost = [sys.executable, "-m", "cdprhost"]
    work = Path(tempfile.mkdtemp(prefix="tui-cpu-"))  # the run's own state and service
    os.environ["CDPRHOST_STATE"] = str(work / "state")
    os.environ["CDPRHOST_RUN"] = str(work / "run")

    dev, port = sim_device()
    where = ["--in-process"] if args.in_process else []
    ui = PtyTerminal(
        tui_argv(*where, "--port", port, str(args.file)), size=(cols, rows), keep=1_000_000
    )
    try:
        shown(ui, "preflight ok", timeout=300)
        time.sleep(3)
        if args.idle_only:
            idle_only(ui.pid, port, args.seconds, cols, rows)
            return
        idle = measure(ui.pid, args.seconds / 2)
        ui.type("sy", pause_s=0.5)
        shown(ui, "PRINTING", timeout=120)
        time.sleep(args.warmup)  # past heating: the machine moves
        windows: list[float] = []
        main0 = main_thread_seconds(ui.pid)
        mark = ui.total
        printing = measure(ui.pid, args.seconds, windows)
        ui_loop = 100.0 * (main_thread_seconds(ui.pid) - main0) / args.seconds
        for word in ("FAILED", "DONE", "CANCELLED"):  # it printed all along
            if ui.shows(word, since=mark):
                raise SystemExit(f"the print ended while measuring ({word}): nothing measured")
        ui.type("\x11y", pause_s=0.5)  # ctrl+q, yes: cancel and quit
    finally:
        ui.stop(grace_s=5.0)
        dev.terminate()
        dev.wait()
        stop_service(port)

    dev, port = sim_device()
    cli = subprocess.Popen(
        [
            *cdprhost,
            "print",
            str(args.file),
            "--profile",
            "paper-prototype",
            "--port",
            port,
            "--log",
            os.devnull,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(15 + args.warmup)  # preflight, heating: the machine moves
        baseline = measure(cli.pid, args.seconds)
    finally:
        cli.send_signal(signal.SIGTERM)
        try:
            cli.wait(timeout=10)
        except subprocess.TimeoutExpired:
            cli.kill()
        dev.terminate()
        dev.wait()

    print(f"file {args.file.name}, terminal {cols}x{rows}, {args.seconds:g} s per measurement")
    print(f"UI connected, idle:        {idle:5.1f} % of one core")
    print(f"UI printing at 1x:         {printing:5.1f} % of one core (target <= 5 %)")
    print("  per 10 s:                " + " ".join(f"{w:.1f}" for w in windows))
    print(f"  of which the UI thread:  {ui_loop:5.1f} % (the rest: job runner and link threads)")
    print(f"CLI printing at 1x (base): {baseline:5.1f} % of one core")
    print(f"UI / CLI while printing:   {printing / baseline if baseline else float('nan'):5.2f}x")


if __name__ == "__main__":
    main()
