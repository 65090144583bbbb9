"""Figures of the AVR firmware: flash/RAM, ISR cycles, step timing, simulator speed, parse rate.

    python bench/firmware.py [--quick]

Builds the firmware and the simavr harness, reads `avr-size`, then streams through the
harness (a real HostLink over the harness's pty at 250000 baud) and reports what the
harness measured:

- ISR worst case: cycle-exact profile of every interrupt (entry to its RETI) over a
  smooth three-module print stream (the demo stream).
- step timing: for step rates of 10k..60k steps/s on all four axes at once, the spread of
  every rising step edge against the firmware's own schedule (phase k of a tick is due a
  fixed time after the tick's compare match); the highest rate whose spread stays within
  5 us with no pulse lost is the figure.
- simulator speed: simulated over wall seconds for the demo stream with the harness
  unpaced (speed-up 100), and its baseline in the same run: the same stream on the Python
  device model at speed-up 100 (device seconds over wall seconds).
- streaming / parse rate: segments of ever shorter duration (5 ms .. 2 ms) streamed by
  the real host link at 250000 baud in real time to the firmware and, as the baseline,
  to the Python model; the highest segment rate each executes with its record exact (no
  underrun). Both have 128 slots, so the host link bounds both alike; the line's own
  limit (payload bytes per segment plus framing) is shown beside it.
- max_step_rate_exact_all_axes: the highest swept rate, on all four axes at once, whose
  record is exact (above it the tick computation overruns and steps go missing).

Simulated-time speed depends on the machine's load; the other figures are in simulated
(device) time and do not.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cdprhost.link import LinkError, open_link
from cdprhost.sim import avr_device
from firmware_protocol.framing import MAX_PAYLOAD, OVERHEAD
from firmware_protocol.segments import (
    RAMP_CONSTANT,
    RAMP_TO_REST,
    SegmentBatch,
    SegmentContext,
    encode_segments,
)
from firmware_protocol.streams import demo_stream, expected_record

CLOCK_HZ = 100_000
BAUD = 250_000


def _stream(
    kind: str, batch: SegmentBatch, *, speedup: float = 1.0, profile: bool = False
) -> tuple[dict[str, Any], list[dict[str, Any]], bool, float]:
    """Stream ``batch`` to a ``sim-device --firmware kind``: (harness stats, record, ok, wall)."""
    tmp = Path(tempfile.mkdtemp())
    stats, record = tmp / "stats.json", tmp / "record.jsonl"
    env = dict(os.environ, **{avr_device.STATS_ENV: str(stats)})
    if profile:
        env["CDPR_SIM_PROFILE_ISR"] = "1"
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", kind]
    cmd += ["--speedup", f"{speedup:g}", "--record", str(record)]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    assert proc.stdout is not None
    path = proc.stdout.readline().strip()
    ok = True
    t0 = time.monotonic()
    try:
        link = open_link(path)
        try:
            link.queue_segments(batch)
            link.wait_idle(600)
        except LinkError:  # an underrun or another device fault: this rate failed
            ok = False
        finally:
            link.close()
    finally:
        wall = time.monotonic() - t0
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    rows = [json.loads(x) for x in record.read_text().splitlines() if x.strip()]
    s = json.loads(stats.read_text()) if stats.exists() else {}
    return s, rows, ok and rows == expected_record(batch), wall


def _rate_batch(rate: int, n: int = 40, ticks: int = 1000) -> SegmentBatch:
    """``n`` segments at ``rate`` steps/s on all four axes, back and forth; the last one
    brakes to rest from the same rate (half the distance)."""
    d = rate * ticks // CLOCK_HZ
    sign = np.where((np.arange(n) // 4) % 2 == 0, 1, -1)
    deltas = np.outer(sign, [d, d, d, d])
    deltas[-1] //= 2
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


def _short_batch(ticks: int, n: int) -> SegmentBatch:
    """``n`` segments of ``ticks`` each, three modules and the extruder at a few kHz."""
    rng = np.random.default_rng(5)
    rate = rng.integers(1000, 4000, size=(n, 4))
    sign = np.where((np.arange(n) // 50) % 2 == 0, 1, -1)[:, None]
    deltas = sign * np.maximum(1, rate * ticks // CLOCK_HZ)
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


def _size() -> dict[str, Any]:
    out = subprocess.run(
        ["avr-size", str(avr_device.ELF)], capture_output=True, text=True, check=True
    ).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    return {
        "flash_bytes": text + data,
        "flash_of_256k_pct": round(100 * (text + data) / 262_144, 1),
        "ram_static_bytes": data + bss,
        "ram_of_8k_pct": round(100 * (data + bss) / 8192, 1),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer rates and shorter streams")
    args = ap.parse_args()
    avr_device.build()
    fig: dict[str, Any] = {
        "command": "python bench/firmware.py" + (" --quick" if args.quick else "")
    }
    fig.update(_size())

    demo = demo_stream(60 if args.quick else 200, seed=3)
    s, _, ok, _ = _stream("avr", demo, profile=True)
    fig["isr_worst_cycles"] = s["isr_profiled_max_cycles"]
    fig["isr_worst_us"] = round(s["isr_profiled_max_cycles"] / 16, 2)
    fig["isr_mean_cycles"] = s["isr_profiled_mean_cycles"]
    fig["isr_profile_record_exact"] = ok

    s, _, ok, _ = _stream("avr", demo, speedup=100.0)
    _, _, py_ok, py_wall = _stream("python", demo, speedup=100.0)
    fig["sim_over_wall_avr"] = round(s["sim_seconds"] / s["wall_seconds"], 2)
    device_s = demo.ticks.sum() / CLOCK_HZ
    fig["baseline_python_device_s_over_wall"] = round(device_s / py_wall, 2)
    fig["demo_record_exact"] = ok and py_ok

    sweep = []
    for rate in [10_000, 30_000, 60_000] if args.quick else range(10_000, 60_001, 10_000):
        s, _, ok, _ = _stream("avr", _rate_batch(rate))
        spread = s["step_err_max_us"] - s["step_err_min_us"]
        good = ok and s["lost_steps"] == 0 and s["unrepaired"] == 0 and spread <= 5.0
        sweep.append(
            {
                "steps_per_s_each_axis": rate,
                "step_err_min_us": s["step_err_min_us"],
                "step_err_max_us": s["step_err_max_us"],
                "spread_us": round(spread, 3),
                "min_pulse_high_us": s["min_pulse_high_us"],
                "min_dir_setup_us": s["min_dir_setup_us"],
                "lost_steps": s["lost_steps"],
                "record_exact": ok,
                "within_5us": good,
            }
        )
    fig["step_timing"] = sweep
    fig["max_step_rate_within_5us"] = max(
        (r["steps_per_s_each_axis"] for r in sweep if r["within_5us"]), default=0
    )

    fig["max_step_rate_exact_all_axes"] = max(
        (r["steps_per_s_each_axis"] for r in sweep if r["record_exact"]), default=0
    )

    # streaming: segments of ever shorter duration until one device underruns; the
    # Python model is the baseline (the host link and its 128-slot window bound both)
    parse = []
    n = 600 if args.quick else 1500
    for ticks in (500, 400, 300, 250, 200):
        batch = _short_batch(ticks, n)
        payload, _ = encode_segments(batch, SegmentContext())
        row = {"segment_ms": ticks / 100, "segments_per_s": CLOCK_HZ // ticks}
        row["payload_bytes_per_segment"] = round(len(payload) / n, 2)
        for kind in ("avr", "python"):
            row[f"{kind}_record_exact"] = _stream(kind, batch)[2]
        parse.append(row)
        if not (row["avr_record_exact"] or row["python_record_exact"]):
            break
    fig["streaming"] = parse
    for kind in ("avr", "python"):
        fig[f"segments_per_s_streamed_{kind}"] = max(
            (p["segments_per_s"] for p in parse if p[f"{kind}_record_exact"]), default=0
        )
    # what 250000 baud carries: 10 bits a byte, full frames of segments
    seg = parse[0]["payload_bytes_per_segment"]
    per_seg = seg * (1 + OVERHEAD / MAX_PAYLOAD)
    fig["segments_per_s_line_limit_250000_baud"] = round(BAUD / 10 / per_seg)
    print(json.dumps(fig, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
