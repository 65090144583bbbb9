"""Stage 1 of the step engine (docs/step-engine.md section 6): its step rates in simavr.

    python firmware/tools/engine_rates.py [--segments 20] [--max-rate N] [--cflags ...] [RATES ...]

Builds the firmware with the step engine (``-DSTEP_ENGINE=1``, MAX_STEP_RATE raised) into
its own build directory (``firmware/build/engine-rate-N``; the tests' build is left
alone), streams steady segments of 10 ms at the given rates (steps/s per axis,
``X,Y,Z,E``; by default the issue's configurations) and judges every rising step edge
against its ideal time on the segment's profile (PROTOCOL.md 5.1). The measuring is
bench/firmware_rates.py's (`python bench/firmware.py --rates --engine` searches the
highest rate of each configuration for both engines); this prints one JSON line per
configuration: worst and 99th percentile of |error| (us), the edges logged per axis, the
tick overruns, the late pulses, the step interrupts' cycles and whether the executed
record is exact.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import firmware_rates

from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segments import SegmentBatch

TICKS = firmware_rates.SEGMENT_TICKS  # 10 ms segments

#: the issue's configurations: one module alone, a print's mix at R = 30,000, three
#: modules out of step at 33,000 with the extruder running
DEFAULT = ["100000,0,0,0", "30000,22500,15000,3000", "33000,32901,32769,3300"]

_build: firmware_rates.Build | None = None


def build(max_rate: int, extra: str = "") -> firmware_rates.Build:
    """The step engine's build announcing ``max_rate`` (``extra``: more build options);
    ``run`` streams to the last one built."""
    global _build
    _build = firmware_rates.variant(max_rate, f"{firmware_rates.ENGINE_CFLAGS} {extra}".strip())
    return _build


def steady_batch(rates: list[int], n: int) -> SegmentBatch:
    """``n`` steady segments at ``rates``, then a pause (the motion ends at rest)."""
    d = np.array(rates, dtype=np.int64) * TICKS // firmware_rates.CLOCK_HZ
    deltas = np.vstack([np.tile(d, (n, 1)), np.zeros((1, 4), dtype=np.int64)])
    return SegmentBatch(
        np.full(n + 1, TICKS), deltas, np.full(n + 1, RAMP_CONSTANT, dtype=np.int16)
    )


def run(rates: list[int], n: int) -> dict[str, Any]:
    """``n`` steady segments at ``rates`` on the last build: the point's figures."""
    if _build is None:
        raise RuntimeError("build() first")
    p = firmware_rates.run_batch(_build, steady_batch(rates, n))
    return {
        "steps_per_s": rates,
        "worst_us": p["worst_us"],
        "p99_us": p["p99_us"],
        "edges": p["edges"],
        "overruns": p["overruns"],
        "late_pulses": p["late_pulses"],
        "isr_cycles": p["isr_cycles"],
        "record_exact": p["record_exact"],
        "fault": p.get("refused"),
        "passed": p["passed"],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
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
