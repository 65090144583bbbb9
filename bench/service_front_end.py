"""A print outlives its front end (issue 32): `cdprhost print` on a pty sim-device, with
busy loops at the same priority, its front end stopped (SIGSTOP) for a while, then killed;
a new `cdprhost print --attach` watches the print to its end.

    python bench/service_front_end.py                      # the cup at 1x: about 13 min
    python bench/service_front_end.py --speedup 10 --stop-at 20 --stop-s 10 --kill-at 40

Prints when each step happened, the watcher's report (status, segments, retransmits) and
whether the device's watchdog fired. Nothing is compared with a time: the outcome is the
figure (completed or not, and why).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "cdprhost"]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--gcode", default=str(ROOT / "examples" / "example.gcode"))
    p.add_argument("--speedup", default="1")
    p.add_argument("--busy", type=int, default=2, help="busy loops at the front end's priority")
    p.add_argument("--stop-at", type=float, default=90.0, help="s after the start: SIGSTOP")
    p.add_argument("--stop-s", type=float, default=30.0, help="how long it stays stopped")
    p.add_argument("--kill-at", type=float, default=180.0, help="s after the start: SIGKILL")
    args = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="svc-bench-"))
    env = {**os.environ, "CDPRHOST_STATE": str(tmp / "state"), "CDPRHOST_RUN": str(tmp / "run")}
    dev = subprocess.Popen(
        [*CLI, "sim-device", "--speedup", args.speedup],
        stdout=subprocess.PIPE,
        stderr=open(tmp / "device.err", "w"),  # noqa: SIM115 - closed with the process
        text=True,
        env=env,
    )
    assert dev.stdout is not None
    port = dev.stdout.readline().strip()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    t0 = time.monotonic()

    def say(text: str) -> None:
        print(f"{time.monotonic() - t0:7.1f} s  {text}", flush=True)

    try:
        front = subprocess.Popen(
            [*CLI, "print", args.gcode, "--profile", "paper-prototype", "--port", port],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
        say(f"print started on {port} with {args.busy} busy loops")
        time.sleep(args.stop_at)
        front.send_signal(signal.SIGSTOP)
        say("front end stopped (SIGSTOP)")
        time.sleep(args.stop_s)
        front.send_signal(signal.SIGCONT)
        say("front end continued")
        time.sleep(max(0.0, args.kill_at - args.stop_at - args.stop_s))
        front.kill()
        front.wait()
        say("front end killed; a new one attaches")
        watch = subprocess.run(
            [*CLI, "print", "--attach", "--port", port],
            check=False,
            capture_output=True,
            text=True,
            env=env,
        )
        say(f"the watcher exited {watch.returncode}")
        print(watch.stdout)
    finally:
        for b in busy:
            b.kill()
        dev.terminate()
        dev.wait(30)
    fired = "host watchdog" in (tmp / "device.err").read_text()
    print(f"device watchdog fired: {fired}")
    return 0 if watch.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
