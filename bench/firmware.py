"""Figures of the AVR firmware: flash/RAM, ISR cycles, step timing, simulator speed, parse rate.

    python bench/firmware.py [--segments N]

Builds the firmware and the simavr harness, reads `avr-size`, then streams N
demo segments through the harness at full speed-up and reports what its stats
file measured (ISR worst case by cycle-exact profiling, minimum pulse width and
step spacing from the pin edges, simulated vs wall time, segments parsed per
second of simulated time). Simulated-time speed depends on the machine's load.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cdprhost.link import open_link
from cdprhost.sim import avr_device
from firmware_protocol.streams import demo_stream


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=400)
    args = ap.parse_args()
    avr_device.build()
    size = (
        subprocess.run(
            ["avr-size", str(avr_device.ELF)], capture_output=True, text=True, check=True
        )
        .stdout.splitlines()[1]
        .split()
    )
    text, data, bss = (int(x) for x in size[:3])
    tmp = Path(tempfile.mkdtemp())
    stats = tmp / "stats.json"
    cmd = avr_device.harness_command(speedup=100.0, stats=str(stats))
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, text=True, env={"CDPR_SIM_PROFILE_ISR": "1"}
    )
    path = proc.stdout.readline().strip()
    batch = demo_stream(args.segments, seed=3, clock_hz=10_000, min_ticks=20, max_ticks=60)
    t0 = time.monotonic()
    try:
        link = open_link(path)
        link.queue_segments(batch)
        link.wait_idle(600)
        link.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    wall = time.monotonic() - t0
    s = json.loads(stats.read_text())
    figures = {
        "flash_bytes": text + data,
        "ram_static_bytes": data + bss,
        "isr_worst_cycles_profiled": s["isr_profiled_max_cycles"],
        "isr_mean_cycles_profiled": s["isr_profiled_mean_cycles"],
        "min_pulse_high_us": s["min_pulse_high_us"],
        "min_step_interval_us": s["min_step_interval_us"],
        "min_dir_setup_us": s["min_dir_setup_us"],
        "sim_over_wall": s["sim_seconds"] / s["wall_seconds"],
        "segments": args.segments,
        "segments_per_sim_second": s["segments_parsed"] / s["sim_seconds"],
        "stream_wall_s": wall,
        "lost_interrupts_repaired": s["repairs"],
        "unrepaired": s["unrepaired"],
    }
    print(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
