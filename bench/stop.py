"""Stop latency and deceleration of pause and cancel (issue 23), in device time at 1x.

    python bench/stop.py            # the example cup (3 layers) and fast circles
    python bench/stop.py --signals  # `cdprhost print` on a pty sim-device at 1x, signalled

Each run prints a file on the embedded device (virtual time: device seconds are link
seconds, as at 1x) and requests a pause or a cancel at a program time; the figures come
from the device's record: seconds from the request to rest (end of the retract), the
speed when the deceleration began, its segments, the peak deceleration between
consecutive segments (mean speeds) against the profile's limit, and the extruder's net
motion after the stop began (the retract only). ``--signals`` measures the wall-clock
seconds from SIGINT / SIGHUP / SIGTERM to the exit of ``cdprhost print`` (on a loaded
machine these are noisy), and the device's state afterwards.

Figures (2026-11-26, 2 shared cores): at rest 0.68-1.18 device s after the request (cup at
20-30 mm/s: 0.89-1.18 s; circles at 120 mm/s: 0.68 s over 7 deceleration segments);
peak deceleration 2082-2113 mm/s^2 from mean segment speeds against the 2000 limit (the
retiming itself is exactly at the limit: tests/motion/test_stop.py); the extruder only
retracts after the stop (-96 steps = 1 mm). Signals: `cdprhost print` exits 2.05-2.16 s
after SIGINT/SIGHUP/SIGTERM, device not faulted, at rest, heaters 0/0.
"""

from __future__ import annotations

import json
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprhost.kinematics.machine import MachineModel  # noqa: E402
from tests.e2e.conftest import first_layers  # noqa: E402
from tests.job.stop_figures import CUP, fast_circles, peak_decel, run_with_request  # noqa: E402


def signals() -> None:
    from cdprhost.link import open_link
    from tests.e2e.processes import SimDeviceProcess, printing_point, square_part, start_print

    print(f"{'signal':7} {'exit s':>6} {'status':9} {'faulted':7} {'busy':5} heaters")
    for sig in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        with tempfile.TemporaryDirectory() as tmp_name:
            tmp = Path(tmp_name)
            state, report = tmp / "state", tmp / "result.json"
            gcode = square_part(tmp / "part.gcode", layers=30)
            with SimDeviceProcess(tmp, "--speedup", "1") as dev:
                host = start_print(gcode, dev.path, state, "--json", str(report))
                printing_point(gcode, state)
                t0 = time.monotonic()
                host.send_signal(sig)
                host.communicate(timeout=120)
                exit_s = time.monotonic() - t0
                status = json.loads(report.read_text())["status"]
                link = open_link(dev.path)
                st = link.request_status()
                link.close()
                print(
                    f"{sig.name:7} {exit_s:6.2f} {status:9} {st.faulted!s:7} {st.busy!s:5} "
                    f"{st.hotend_target_c:g}/{st.bed_target_c:g}"
                )


def main() -> None:
    if "--signals" in sys.argv[1:]:
        signals()
        return
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        cup = first_layers(CUP, tmp, 3, ("M104 S0", "M140 S0"))
        fast = fast_circles(tmp / "fast.gcode")
        cases = [
            ("cup", cup, "cancel", 40.0),
            ("cup", cup, "cancel", 75.0),
            ("cup", cup, "pause", 60.0),
            ("fast", fast, "cancel", 6.0),
            ("fast", fast, "pause", 9.0),
        ]
        print(
            f"{'file':5} {'request':7} {'at s':>5} {'latency s':>9} {'v0 mm/s':>8} "
            f"{'segments':>8} {'peak decel':>10} {'limit':>6} {'e after':>7} status"
        )
        for name, path, what, at in cases:
            run = run_with_request(path, what, at, tmp / f"{name}-{what}-{at:g}")
            stop = run.stop
            model = MachineModel.from_profile(run.job.profile)
            e0 = run.by_seq(stop.first_segment - 1)["steps"][3]
            e1 = run.by_seq(stop.last_segment)["steps"][3]
            print(
                f"{name:5} {what:7} {at:5.0f} {run.latency_s:9.3f} {stop.v0:8.1f} "
                f"{stop.last_segment - stop.first_segment + 1:8d} "
                f"{peak_decel(model, run.window()):10.0f} {stop.accel:6.0f} {e1 - e0:7d} "
                f"{run.result.status}"
            )


if __name__ == "__main__":
    main()
