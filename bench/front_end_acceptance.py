"""The long front-end acceptance runs of issue 32: a real `cdprhost tui` in a pseudo-terminal
prints the cup on a pty `cdprhost sim-device`, through the printer service, while

- ``busy``: busy loops run at the TUI's own priority for the whole print;
- ``sigstop``: the TUI is stopped (SIGSTOP) for ``--stop-s`` s mid-print, then continued;
- ``kill``: the TUI is killed (SIGKILL) mid-print; a new `cdprhost tui` attaches and its
  screen shows the print to its end (DONE);
- ``watch``: a second front end, `cdprhost print --attach`, watches the print the TUI
  started; both must report the same end (state, layer).

    python bench/front_end_acceptance.py                       # all four at 1x: ~15 min
    python bench/front_end_acceptance.py --only kill,watch --speedup 10

The scenarios run at the same time, each with its own state folder, service and device; the
busy loops (``--busy``, default 2) are shared by all. Per scenario the report says whether the
print completed, the device's record (segments executed), the service's link counters
(retransmissions, NAKs), underruns, whether the device's host watchdog fired and the wall
time; the load average is printed before and after. Nothing is compared with a time: the
outcome (completed or not, and why) is the figure.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.tui.pty_terminal import PtyTerminal, tui_argv  # noqa: E402

CLI = [sys.executable, "-m", "cdprhost"]
SCENARIOS = ("busy", "sigstop", "kill", "watch")


def _device_priority(step: int) -> Callable[[], None]:
    """The simulated device stands for a board with a processor of its own: it runs ``step``
    nice values above the rest when allowed (as the super-user), so that the host's
    stream, not the device model, is what a loaded machine tests."""

    def lower() -> None:
        with contextlib.suppress(OSError):
            os.nice(-step)

    return lower


def nice_of(pid: int) -> int | None:
    """The nice value of process ``pid`` (None when it has gone)."""
    try:
        return os.getpriority(os.PRIO_PROCESS, pid)
    except OSError:
        return None


@dataclass
class Outcome:
    name: str
    steps: list[str] = field(default_factory=list)
    completed: bool = False
    end_state: str = ""
    segments: int = 0
    retransmits: int = -1
    naks: int = -1
    underruns: int = 0
    watchdog: bool = False
    nice: str = ""
    wall_s: float = 0.0
    screen: str = ""
    watcher: str = ""
    error: str = ""


class Scenario:
    """One print of ``gcode`` from a TUI, with its own device, state folder and service."""

    def __init__(self, name: str, args: argparse.Namespace, t0: float):
        self.name = name
        self.args = args
        self.t0 = t0
        self.tmp = Path(tempfile.mkdtemp(prefix=f"fe-{name}-"))
        self.state = self.tmp / "state"
        self.env = {
            **os.environ,
            "CDPRHOST_STATE": str(self.state),
            "CDPRHOST_RUN": str(self.tmp / "run"),
        }
        self.out = Outcome(name)
        self.record = self.tmp / "record.jsonl"
        self.device: subprocess.Popen[str] | None = None
        self.port = ""
        self.tuis: list[PtyTerminal] = []

    def say(self, text: str) -> None:
        line = f"{time.monotonic() - self.t0:7.1f} s  {self.name:8s} {text}"
        self.out.steps.append(line)
        print(line, flush=True)

    # -- the pieces -----------------------------------------------------------------------

    def start_device(self) -> None:
        self.device = subprocess.Popen(
            [*CLI, "sim-device", "--speedup", self.args.speedup, "--record", str(self.record)],
            stdout=subprocess.PIPE,
            stderr=open(self.tmp / "device.err", "w"),  # noqa: SIM115 - closed with the process
            text=True,
            env=self.env,
            preexec_fn=_device_priority(self.args.device_nice),  # noqa: PLW1509
        )
        assert self.device.stdout is not None
        self.port = self.device.stdout.readline().strip()

    def tui(self, *extra: str) -> PtyTerminal:
        argv = tui_argv("--profile", "paper-prototype", "--port", self.port, *extra)
        program = PtyTerminal(argv, size=self.args.size, env=self.env)
        self.tuis.append(program)
        return program

    def job_log(self) -> list[dict[str, Any]]:
        logs = sorted((self.state / "jobs").glob("*.jsonl"))
        if not logs:
            return []
        rows = []
        for line in logs[-1].read_text().splitlines():
            with contextlib.suppress(ValueError):
                rows.append(json.loads(line))
        return rows

    def job_state(self) -> str:
        states = [r["state"] for r in self.job_log() if r.get("event") == "StateChanged"]
        return states[-1] if states else ""

    def executed(self) -> int:
        if not self.record.exists():
            return 0
        return sum(1 for line in self.record.read_text().splitlines() if line.strip())

    def wait(self, cond: Callable[[], object], timeout: float, what: str) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if cond():
                return True
            time.sleep(0.5)
        self.out.error = self.out.error or f"timed out waiting for {what}"
        self.say(f"timed out waiting for {what}")
        return False

    def start_print(self, tui: PtyTerminal) -> bool:
        """s, then y in the confirmation, until the service's job log says it prints (the
        TUI connects and preflights first: a key before that only warns)."""
        end = time.monotonic() + self.args.start_timeout
        while time.monotonic() < end:
            if self.job_state() in ("printing", "heating"):
                self.say("printing (s, y in the TUI)")
                return True
            if tui.proc.poll() is not None:
                self.out.error = f"the TUI exited {tui.proc.returncode} before printing"
                return False
            tui.type("s")
            time.sleep(1.5)
            tui.type("y")
            time.sleep(3.0)
        self.out.error = "the print did not start from the TUI"
        return False

    def past(self, seconds: float) -> bool:
        """Wait until the device has executed segments for ``seconds`` after the first (the
        heating first: mid-print means moving)."""
        first: list[float] = []

        def moving() -> bool:
            if self.executed() > 0 and not first:
                first.append(time.monotonic())
            return bool(first) and time.monotonic() - first[0] >= seconds

        return self.wait(moving, self.args.timeout, "the print to move")

    def ended_early(self) -> bool:
        """The print ended before its scenario's signal (then there is nothing to try)."""
        if self.finished():
            self.say(f"the print ended ({self.job_state()}) before the signal")
            return True
        return False

    def finished(self) -> bool:
        return self.job_state() in ("done", "failed", "cancelled")

    # -- the scenarios --------------------------------------------------------------------

    def run(self) -> Outcome:
        start = time.monotonic()
        try:
            self.start_device()
            self.say(f"device on {self.port} (speedup {self.args.speedup})")
            tui = self.tui(str(self.args.gcode))
            if self.start_print(tui):
                getattr(self, f"_{self.name}")(tui)
        except Exception as exc:  # noqa: BLE001 - a bench reports; the other scenarios go on
            self.out.error = f"{type(exc).__name__}: {exc}"
        finally:
            self.out.wall_s = time.monotonic() - start
            self._cleanup()  # the device's record is complete once it has exited
            self._collect()
        return self.out

    def _busy(self, tui: PtyTerminal) -> None:
        self.wait(self.finished, self.args.timeout, "the end of the print")

    def _sigstop(self, tui: PtyTerminal) -> None:
        if not self.past(self.args.mid_s) or self.ended_early():
            return
        before = self.executed()
        tui.proc.send_signal(signal.SIGSTOP)
        self.say(f"TUI stopped (SIGSTOP) at segment {before}")
        time.sleep(self.args.stop_s)
        during = self.executed() - before
        tui.proc.send_signal(signal.SIGCONT)
        self.say(f"TUI continued; the device executed {during} segments meanwhile")
        self.wait(self.finished, self.args.timeout, "the end of the print")
        self.wait(lambda: tui.shows("DONE"), 60, "DONE on the TUI's screen")

    def _kill(self, tui: PtyTerminal) -> None:
        if not self.past(self.args.mid_s) or self.ended_early():
            return
        tui.proc.kill()
        tui.proc.wait(30)
        self.say(f"TUI killed (SIGKILL) at segment {self.executed()}")
        time.sleep(2.0)
        if self.finished():
            self.out.error = f"the print ended with its TUI: {self.job_state()}"
            return
        again = self.tui()
        name = Path(self.args.gcode).name
        if self.wait(lambda: again.shows(name) and again.shows("PRINTING"), 180, "the new TUI"):
            self.say("a new TUI attached and shows the print")
            self.out.screen = "shows the print"
        self.wait(self.finished, self.args.timeout, "the end of the print")
        if self.wait(lambda: again.shows("DONE"), 120, "DONE on the new TUI's screen"):
            self.out.screen += ", then DONE"

    def _watch(self, tui: PtyTerminal) -> None:
        report = self.tmp / "watch.json"
        watcher = subprocess.Popen(
            [*CLI, "print", "--attach", "--port", self.port, "--json", str(report)],
            stdout=subprocess.DEVNULL,
            stderr=open(self.tmp / "watch.err", "w"),  # noqa: SIM115 - closed with the process
            env=self.env,
        )
        self.say("`cdprhost print --attach` watches")
        try:
            watcher.wait(self.args.timeout)
        except subprocess.TimeoutExpired:
            watcher.kill()
            self.out.error = "the watcher did not see the end"
        self.wait(self.finished, 60, "the end of the print")
        if not report.exists():
            self.out.watcher = f"no report (exit {watcher.returncode})"
            return
        seen = json.loads(report.read_text())
        self.out.watcher = (
            f"status {seen.get('status')}, last layer {seen.get('last_layer')}, "
            f"segments {seen.get('segments')}"
        )
        layers = f"{seen.get('last_layer')}/{seen.get('last_layer')}"
        self.wait(lambda: tui.shows("DONE") and tui.shows(layers), 60, "DONE on the TUI")
        self.out.screen = f"DONE {layers}" if tui.shows("DONE") and tui.shows(layers) else "no DONE"
        progress = [r for r in self.job_log() if r.get("event") == "Progress"]
        done = progress[-1].get("segments_done") if progress else None
        self.out.watcher += f" (the job log's last progress: segment {done})"
        if seen.get("status") != "completed" or "DONE" not in self.out.screen:
            self.out.error = f"the watcher saw {self.out.watcher}; the TUI {self.out.screen}"

    # -- the figures ----------------------------------------------------------------------

    def _collect(self) -> None:
        log = self.job_log()
        self.out.end_state = self.job_state()
        self.out.completed = any(
            r.get("event") == "StateChanged" and r.get("state") == "done" for r in log
        )
        health = [r for r in log if r.get("event") == "LinkHealth"]
        if health:
            self.out.retransmits = int(health[-1].get("retransmits", -1))
            self.out.naks = int(health[-1].get("naks", -1))
        failures = [r for r in log if r.get("event") == "Failure"]
        self.out.underruns = sum("underrun" in str(r.get("reason", "")) for r in failures)
        if failures:  # the cause first: what the waits saw follows from it
            self.out.error = f"the print failed: {failures[-1].get('reason')}"
        self.out.segments = self.executed()
        err = (self.tmp / "device.err").read_text() if (self.tmp / "device.err").exists() else ""
        self.out.watchdog = "host watchdog" in err

    def _cleanup(self) -> None:
        for n, program in enumerate(self.tuis):
            (self.tmp / f"tui{n}.screen.txt").write_text(program.screen())
            program.stop()
        from cdprhost.service.paths import files_for_port

        saved = {k: os.environ.get(k) for k in ("CDPRHOST_STATE", "CDPRHOST_RUN")}
        os.environ.update({k: self.env[k] for k in saved})  # where this scenario's service is
        try:
            pid = files_for_port(self.port).read_pid() if self.port else None
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        if pid:
            ui = self.tuis[0].proc.pid if self.tuis else None
            self.out.nice = (
                f"service {nice_of(pid)}, device {nice_of(self.device.pid) if self.device else None}"
                f", TUI {nice_of(ui) if ui else None}"
            )
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGTERM)
        if self.device is not None:
            self.device.terminate()
            try:
                self.device.wait(30)
            except subprocess.TimeoutExpired:
                self.device.kill()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--gcode", default=str(ROOT / "examples" / "example.gcode"))
    p.add_argument("--speedup", default="1")
    p.add_argument("--only", default=",".join(SCENARIOS), help="comma-separated scenarios")
    p.add_argument("--busy", type=int, default=2, help="busy loops (shared by the scenarios)")
    p.add_argument("--mid-s", type=float, default=120.0, help="s of moving before stop/kill")
    p.add_argument("--stop-s", type=float, default=30.0, help="how long SIGSTOP lasts")
    p.add_argument("--timeout", type=float, default=3600.0, help="longest wait for an end, s")
    p.add_argument("--start-timeout", type=float, default=300.0)
    p.add_argument("--size", type=lambda s: tuple(map(int, s.split("x"))), default=(120, 40))
    p.add_argument(
        "--device-nice",
        type=int,
        default=10,
        help="run the simulated device this many nice values above the rest when allowed "
        "(it stands for a board's own processor; 0: as the rest)",
    )
    p.add_argument("--json", metavar="FILE", help="write the outcomes as JSON")
    args = p.parse_args()
    names = [n for n in args.only.split(",") if n]
    unknown = set(names) - set(SCENARIOS)
    if unknown:
        p.error(f"unknown scenario(s) {sorted(unknown)}; known: {', '.join(SCENARIOS)}")
    print(f"load average before: {os.getloadavg()}", flush=True)
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    t0 = time.monotonic()
    outcomes: dict[str, Outcome] = {}
    loads: list[float] = []
    stop = threading.Event()

    def sample_load() -> None:
        while not stop.wait(30):
            loads.append(os.getloadavg()[0])

    threading.Thread(target=sample_load, daemon=True).start()
    try:
        runs = [Scenario(n, args, t0) for n in names]
        threads = [
            threading.Thread(target=lambda s=s: outcomes.__setitem__(s.name, s.run())) for s in runs
        ]
        for t in threads:
            t.start()
            time.sleep(1.0)
        for t in threads:
            t.join()
    finally:
        stop.set()
        for b in busy:
            b.kill()
    print(f"load average after: {os.getloadavg()}", flush=True)
    if loads:
        print(
            f"1-min load average during: mean {sum(loads) / len(loads):.2f}, max {max(loads):.2f}"
        )
    print(f"busy loops: {args.busy} at the TUI's priority; speedup {args.speedup}")
    header = (
        "scenario  completed  end        segments  retransmits  naks  underruns  watchdog  wall"
    )
    print(header)
    for name in names:
        o = outcomes[name]
        print(
            f"{name:9s} {o.completed!s:10s} {o.end_state:10s} {o.segments:8d}  {o.retransmits:11d}"
            f"  {o.naks:4d}  {o.underruns:9d}  {o.watchdog!s:8s}  {o.wall_s:6.0f} s"
        )
        for extra in (
            o.screen and f"screen: {o.screen}",
            o.watcher and f"watcher: {o.watcher}",
            o.nice and f"nice values: {o.nice}",
        ):
            if extra:
                print(f"          {extra}")
        if o.error:
            print(f"          error: {o.error}")
    if args.json:
        Path(args.json).write_text(json.dumps({n: vars(o) for n, o in outcomes.items()}, indent=2))
    return 0 if all(o.completed and not o.error for o in outcomes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
