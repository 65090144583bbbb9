"""The estimate for the board against the print it makes, on a device announcing a board's limits.

    python bench/board_estimate.py [--gcode examples/example.gcode] [--profile paper-prototype]
                                   [--rate 8000] [--min-ticks 40]

Prints JSON figures:

- ``estimate_s``: what `check` and `print` say with the board's record (the profile's
  ``[device]`` table: ``--rate`` steps/s, ``--min-ticks`` x 10 us);
- ``estimate_profile_limits_s``: the same without the record (what they said before);
- ``printed_s``: the print's device time on the Python device announcing those limits (the
  embedded device, as fast as the CPU allows; the job's own estimate, planned again on what
  the device announced, as ``job_estimate_s``);
- the errors of both estimates against the print, and the board's message.

The AVR firmware announces 8,000 steps/s and 40 ticks (firmware/src/config.h); the print
on the AVR itself runs in real time in simavr: `cdprhost sim-device --firmware avr`, then
`cdprhost print FILE --profile P --port PTY` (which records the board beside the profile)
and `cdprhost check FILE --profile P` (which then estimates for it).

Measured (issue 29, before the step engine; 8,000 steps/s and 40 ticks announced):

| the cup, paper-prototype | device time |
|---|---|
| on the AVR in simavr (`sim-device --firmware avr`, `print --port`; 33 min of real time) | 1147.42 s |
| on the Python device at the same limits (this script's `printed_s`) | 1147.42 s |
| `check` and `print` with the board's record (`estimate_s`) | 1145.42 s (-0.17 %) |
| planned with no step-rate cap (`estimate_profile_limits_s`) | 744.59 s (the board: +54 %) |

The estimate's 2.00 s are the `G28` at the start: the homing run (8,000 steps at the
homing rate of 4,000 steps/s) counts in the device's motion time and not in the plan.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from cdprhost.job.runner import PrintJob, PrintOptions
from cdprhost.preflight.run import preflight
from cdprhost.profile import DeviceRecord, load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gcode", default="examples/example.gcode")
    ap.add_argument("--profile", default="paper-prototype")
    ap.add_argument("--rate", type=int, default=8_000, help="steps/s the board announces")
    ap.add_argument("--min-ticks", type=int, default=40, help="its shortest segment, 10 us ticks")
    args = ap.parse_args()
    cfg = SimConfig(max_step_rate=args.rate, min_segment_ticks=args.min_ticks)
    record = DeviceRecord(max_step_rate=args.rate, min_segment_s=args.min_ticks / cfg.clock_hz)
    profile = load_profile(args.profile).model_copy(update={"device": None})
    t0 = time.perf_counter()
    plain = preflight(args.gcode, profile)
    t1 = time.perf_counter()
    board = preflight(args.gcode, profile.model_copy(update={"device": record}))
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        job = PrintJob(
            Path(args.gcode),
            profile,
            lambda: open_embedded(config=cfg, record_keep=1000),
            PrintOptions(log_path=Path(tmp) / "job.jsonl", resume_dir=tmp),
        )
        result = job.run()
    printed = result.print_time_s

    def err(x: float) -> float:
        return round(100.0 * (x - printed) / printed, 2)

    figures = {
        "gcode": args.gcode,
        "profile": args.profile,
        "board": {"max_step_rate": args.rate, "min_segment_ticks": args.min_ticks},
        "status": result.status,
        "printed_s": round(printed, 3),
        "estimate_s": board.estimated_time_s,
        "estimate_error_pct": err(board.estimated_time_s),
        "estimate_profile_limits_s": plain.estimated_time_s,
        "estimate_profile_limits_error_pct": err(plain.estimated_time_s),
        "job_estimate_s": result.estimated_time_s,
        "board_message": board.board.message if board.board else "",
        # the second planner costs this much more than the check without a record
        "check_time_ratio_with_board": round((t2 - t1) / (t1 - t0), 2),
    }
    print(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
