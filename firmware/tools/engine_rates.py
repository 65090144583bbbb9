"""Stage 1 of the step engine (docs/step-engine.md section 6): its step rates in simavr.

    python firmware/tools/engine_rates.py [--segments 20] [RATES ...]

Builds the firmware with the step engine (``-DSTEP_ENGINE=1``, MAX_STEP_RATE raised) into
``firmware/build-engine`` (the tests' build is left alone), runs its harness directly and
streams steady segments of 10 ms at the given rates (steps/s per axis, ``X,Y,Z,E``; by
default the issue's configurations), then sets every rising step edge against its ideal
time on the segment's profile (PROTOCOL.md 5.1). Prints one JSON line per configuration:
worst and 99th percentile of |error| (us), the tick overruns, the late pulses and whether
the executed record is exact.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from cdprhost.link import LinkError, open_link
from firmware_protocol.segments import RAMP_CONSTANT, SegmentBatch, step_times
from firmware_protocol.streams import expected_record

FIRMWARE = Path(__file__).resolve().parents[1]
BUILD = FIRMWARE / "build-engine"
CLOCK_HZ = 100_000
CYCLES_PER_US = 16
TICKS = 1000  # 10 ms segments

#: the issue's configurations: one module alone, a print's mix at R = 30,000, three
#: modules out of step at 33,000 with the extruder running
DEFAULT = ["100000,0,0,0", "30000,22500,15000,3000", "33000,32901,32769,3300"]


def build(max_rate: int, extra: str = "") -> None:
    flags = f"-DSTEP_ENGINE=1 -DMAX_STEP_RATE={max_rate}UL {extra}".strip()
    cmd = ["make", "-s", "-B", "-C", str(FIRMWARE), "BUILD=build-engine", f"EXTRA_CFLAGS={flags}"]
    subprocess.run([*cmd, "all", "sim"], check=True)  # -B: the options change, not the files


def steady_batch(rates: list[int], n: int) -> SegmentBatch:
    """``n`` steady segments at ``rates``, then a pause (the motion ends at rest)."""
    d = np.array(rates, dtype=np.int64) * TICKS // CLOCK_HZ
    deltas = np.vstack([np.tile(d, (n, 1)), np.zeros((1, 4), dtype=np.int64)])
    return SegmentBatch(
        np.full(n + 1, TICKS), deltas, np.full(n + 1, RAMP_CONSTANT, dtype=np.int16)
    )


def ideal_us(batch: SegmentBatch, axis: int) -> np.ndarray:
    starts = np.concatenate([[0], np.cumsum(batch.ticks)[:-1]])
    parts = [
        starts[i] + step_times(int(batch.deltas[i, axis]), int(batch.ticks[i]), int(batch.ramps[i]))
        for i in range(len(batch))
    ]
    return np.concatenate(parts) * 1e6 / CLOCK_HZ


def run(rates: list[int], n: int) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp())
    log, record, stats = tmp / "steps.txt", tmp / "record.jsonl", tmp / "stats.json"
    env = {**os.environ, "CDPR_SIM_STEP_LOG": str(log)}
    cmd = [str(BUILD / "cdpr-sim"), str(BUILD / "cdpr-sim.elf"), "--speedup", "4"]
    cmd += ["--record", str(record), "--stats", str(stats)]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    batch = steady_batch(rates, n)
    fault = None
    try:
        assert proc.stdout is not None
        link = open_link(proc.stdout.readline().strip())
        try:
            link.queue_segments(batch)
            link.wait_idle(300)
        except LinkError as err:
            fault = str(err)
        finally:
            link.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    rows = [json.loads(x) for x in record.read_text().splitlines() if x.strip()]
    s = json.loads(stats.read_text()) if stats.exists() else {}
    edges = np.loadtxt(log, dtype=np.int64, ndmin=2)
    errs, counts = [], []
    for axis in range(4):
        want = ideal_us(batch, axis)
        got = edges[edges[:, 0] == axis, 1] / CYCLES_PER_US
        counts.append(f"{len(got)}/{len(want)}")
        m = min(len(got), len(want))
        errs.append(np.abs(got[:m] - want[:m]))
    every = np.concatenate(errs)
    return {
        "steps_per_s": rates,
        "worst_us": round(float(every.max()), 2),
        "p99_us": round(float(np.percentile(every, 99)), 2),
        "edges": counts,
        "overruns": s.get("overruns"),
        "late_pulses": s.get("late_pulses"),
        "record_exact": rows == expected_record(batch) and fault is None,
        "fault": fault,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rates", nargs="*", default=DEFAULT, help="X,Y,Z,E steps/s")
    ap.add_argument("--segments", type=int, default=20)
    ap.add_argument("--max-rate", type=int, default=200_000, help="MAX_STEP_RATE of the build")
    ap.add_argument("--cflags", default="", help="more build options, e.g. -DSTEP_PARTNERS=1")
    args = ap.parse_args()
    build(args.max_rate, args.cflags)
    for r in args.rates:
        print(json.dumps(run([int(x) for x in r.split(",")], args.segments)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
