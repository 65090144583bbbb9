"""Figures of the AVR firmware: flash/RAM/stack, ISR load, step timing, streaming, watchdog.

    python bench/firmware.py [--quick] [--stream-rate STEPS_PER_S]
    python bench/firmware.py --rates        # only the highest-rate search (about 20 s)
    python bench/firmware.py --acceptance   # only issue 29's acceptance rows, as a table
    python bench/firmware.py --heaters      # only the heater rows
    python bench/firmware.py --rates --engine [--steady] [--lowest N] [--cflags OPTS]
    python bench/firmware.py --acceptance --engine

Builds the firmware and the simavr harness, reads `avr-size`, then streams through the
harness (a real HostLink over the harness's pty at 250000 baud, in real time) and reports
what the harness measured:

- ISR worst case and mean: cycle-exact profile of every step interrupt (entry to its RETI)
  over a smooth three-module print stream (the demo stream); the stack's high-water mark
  (the firmware paints the gap below the stack at boot).
- step timing: constant rates of 2.5k..10k steps/s (10k: the advertised rate, read from
  firmware/src/config.h) on all four axes at once; every rising step edge against the
  step's exact time on its segment's profile (PROTOCOL.md 5.1), worst and 99th
  percentile; the step interrupts' load (compare A with compare B nested in it, plus
  compare B on its own, over the motion's cycles); the record exact, no pulse lost or
  late.
- streaming: segments of 2 ms down to 0.4 ms (500..2500 segments/s, down to the device's
  shortest segment, a few seconds of device time each) at 1x, on a clean line and with
  `--faults corrupt=0.001,drop=0.001`: record exact or not, the host's retransmissions,
  the longest main-loop turn; the line's own limit beside it. Then the issue's measure,
  30 s of device time: 2000/s clean and 1000/s with the faults.
- a print's mix: one module at 60-100 % of the advertised rate, the others at 3/4 and 1/2
  of it and the extruder at 1/10, so the steps fall apart (each its own compare B): the
  same figures, with the ticks that overran (computed after their start: their steps
  keep their times) and the harness's clock slips (its step log is then off by a tick).
- then bench/firmware_measure.py's measurements, each described there: heaters off
  after the host's silence in each device state, a relay autotune of the hotend on each
  device (`--heaters` runs only these rows), the highest step rate per configuration
  (`--rates`), streaming with print-like segments, the cup on the announced limits.
- `--acceptance`: issue 29's acceptance rows as a table (bench/firmware_acceptance.py).

Baseline (issue 29, today's firmware: a 400 us tick DDA announcing 8,000 steps/s; the
machine shared with four other sessions, 2 cores):

| configuration | highest R (steps/s) | worst / p99 edge at R | ISR load at R | first fail |
|---|---|---|---|---|
| one module alone | 39,500 | 6.2 / 3.0 us | 73 % | 40,000: overrun (16 steps a tick) |
| three modules in step | 18,500 | 6.3 / 4.9 us | 54 % | 19,000: overrun |
| three out of step, extruder 0.1 R | 11,000-11,500 | 7.5 / 4.9 us | 57-66 % | 11,500-12,000: edge 12.5-14.8 us or p99 5.4 us |
| a print's mix | 10,500-11,000 | 7.6 / 4.9 us | 55-56 % | 11,000-11,500: edge 12.5 us or p99 5.2 us (overruns from 14,000) |
| the mix with ramps from rest to that R and back | fails | 5.7-13.0 / 4.1-5.0 us | 60 % | 5 overruns |

The step interrupts take 7.9 % of the CPU with nothing moving (`--rates`, 15-20 s).
Print-like streams at 7,200 steps/s (4.1 payload bytes a segment, 97 % of segments
differ from the one before): exact at 500, 1,000 and 1,250 segments/s; 1,538/s and
2,000/s underrun (at 1.1 s and at 0.3 s of device time, the latter in every run, also
with the simulator on time); 1,000/s with the faults underran at 6-11 s. At 2,000/s the
limit is the CPU, not the line: with the busiest module at 2,000 steps/s (3.8 bytes a
segment) the stream is exact, at 4,000 (3.6 bytes) it underruns at 0.6 s. The older
repeating stream (1.1 bytes a segment) is exact at 2,000/s for 30 s. The cup on the
announced limits: 1147.4 s against 744.6 s without a cap (+54 %); the estimate with the
board's record 1145.4 s (-0.17 %). `--acceptance` today: the three rate rows, the cup's
+1 % and both 30 s print-like streams fail; the estimate (-0.17 %), heaters off
(0.005 s) and the stack (79 B free, flash 42,262 B, RAM 7,585 B) pass.

The step engine beside it (issue 29 Deliver 5; `--engine`: firmware/src/step_engine.c
built with `-DSTEP_ENGINE=1 -DMAX_STEP_RATE=N` into firmware/build/engine-rate-N; the
harness now profiles every step interrupt of either engine, Timer1 A/B, Timer3 A-C and
Timer5 A, so the ISR load counts the engine's steps), 2026-11-29, 2 cores shared with
three other sessions. `python bench/firmware.py --rates --engine`, the points braking
to rest on a ramp as above:

| configuration | engine | highest R (steps/s) | worst / p99 edge at R | ISR load at R | first fail |
|---|---|---|---|---|---|
| one module alone | default (tick DDA) | 39,500 | 5.98 / 3.04 us | 72.7 % | 40,000: overrun |
| one module alone | step engine | 40,000 | 7.56 / 1.19 us | 39.7 % | 40,500: overrun |
| three modules in step | default | 18,500 | 6.28 / 4.97 us | 53.8 % | 19,000: overrun |
| three modules in step | step engine | 11,000 | 8.92 / 1.95 us | 37.4 % | 11,500: overrun |
| three out of step, extruder 0.1 R | default | 10,500 | 8.16 / 4.48 us | 64.5 % | 11,000: edge 10.8 us |
| three out of step, extruder 0.1 R | step engine | none | 12.62 / 12.36 us at 1,000 | 15.7 % | 1,000: edge 12.6 us |
| a print's mix | default | 11,000 | 8.22 / 4.83 us | 56.2 % | 11,500: p99 5.16 us |
| a print's mix | step engine | none | 18.75 / 13.62 us at 1,000 | 15.9 % | 1,000: edge 18.8 us |
| the mix with ramps from rest to 11,000 and back | default | fails: 5 overruns | 8.08 / 5.05 us | 59.7 % | |

The engine steps steady segments only: the braking segment runs on the tick's DDA, so
one module stops at the DDA's 16 steps a tick, and its errors reach 2-4 ms at higher R
(a print's mix at 30,000: 2,111 / 392 us, 15 overruns). Axes under about 1,000 steps/s
are 12-19 us late on every edge (a constant offset: p99 = worst; the extruder at 100/s,
Z at 500/s, Y at 750/s of R = 1,000), so the out-of-step and mix searches fail at their
start. `--steady` ends each point with a stop (a segment at rest after full speed)
instead: `--rates --engine --steady --lowest 10000`: one module 40,000 (DDA) against
97,000 on the engine (6.32 / 3.88 us, 75.1 %; 97,500: an edge a timer period late,
4.1 ms), three in step 40,000 (6.75 / 4.0 us, 87.8 %) against 27,500 (8.45 / 4.59 us,
70.6 %), three out of step 11,000 (7.11 / 4.94 us, 64.5 %) against none (p99 5.11 us at
10,000), the mix 18,500 (7.81 / 4.84 us, 75.5 %) against 16,000 (7.12 / 1.25 us,
37.6 %); with ramps both fail (91 and 74 overruns). From 1,000 (`--steady`) the engine
reaches 106,500 alone (7.61 / 3.35 us, 81.5 %) and 20,000 in step (then an edge 4.1 ms
late). The searches bisect as if a failure at R meant one above it, which neither
engine quite keeps (the mix on the engine passes at 30,000 with a stop: 9.81 / 4.79 us;
three in step on the DDA failed at 18,500 once and passed at 40,000 in another run):
read R as "passes here", not as the edge of a clean range. The issue's rate rows
(`--acceptance --engine`, braking): the mix at 30,000, default 558 overruns, engine 15
overruns (with a stop: passes, 9.81 / 4.79 us); three out of step at 33,000, default 578
overruns, engine 72 (with a stop: 59 overruns, 24.97 / 5.56 us); one module at 100,000,
default overruns, engine 4 overruns (with a stop: passes, 6.25 / 3.56 us). The step
interrupts with nothing moving: 7.9 % of the CPU on the default build, 8.9 % on the
engine's.

Real-time runs depend on the machine's load (simavr must keep up with 1x); the step
timing and ISR figures are in simulated time and do not.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import firmware_acceptance as acceptance
import firmware_measure as measure
import firmware_rates as rates_bench
from firmware_rates import CLOCK_HZ

from cdprhost.sim import avr_device
from firmware_protocol.framing import OVERHEAD
from firmware_protocol.segments import SegmentContext, encode_segments
from firmware_protocol.streams import demo_stream

BAUD = 250_000


def _arguments() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer rates and shorter streams")
    ap.add_argument("--heaters", action="store_true", help="only the heater rows")
    ap.add_argument("--rates", action="store_true", help="only the highest-rate search")
    ap.add_argument(
        "--acceptance", action="store_true", help="only issue 29's acceptance rows, as a table"
    )
    ap.add_argument(
        "--stream-rate",
        type=int,
        default=None,
        help="the busiest module's steps/s in the print-like streams (default: 90 %% of the "
        "rate the firmware announces, as the host plans)",
    )
    ap.add_argument(
        "--engine",
        action="store_true",
        help="--rates/--acceptance: measure the step engine (STEP_ENGINE=1) beside the "
        "default engine, in one table",
    )
    ap.add_argument(
        "--cflags",
        default="",
        help="--rates/--acceptance: measure a build with these options too "
        "(e.g. '-DSTEP_ENGINE=1 -DSTEP_PARTNERS=1')",
    )
    ap.add_argument(
        "--steady",
        action="store_true",
        help="--rates: the points end with a stop (a segment at rest) instead of braking on "
        "a ramp (the step engine steps steady segments only; ramps run on the tick's DDA)",
    )
    ap.add_argument(
        "--lowest",
        type=int,
        default=1_000,
        help="--rates: the R each search starts from (steps/s; default 1000)",
    )
    return ap.parse_args()


def _engines(args: argparse.Namespace) -> list[str]:
    """The build options of each engine to measure: the default engine (the baseline)
    first, then the step engine (``--engine``) and ``--cflags``'s build."""
    out = [""]
    if args.engine:
        out.append(rates_bench.ENGINE_CFLAGS)
    if args.cflags:
        out.append(args.cflags)
    return list(dict.fromkeys(out))


def _flags(args: argparse.Namespace) -> str:
    """The engine options of this run as they are typed, for the command line printed."""
    flags: str = " --engine" * args.engine + " --steady" * args.steady
    flags += f" --lowest {args.lowest}" if args.lowest != 1_000 else ""
    flags += f" --cflags '{args.cflags}'" if args.cflags else ""
    return flags


def _print_rates(args: argparse.Namespace) -> None:
    """`--rates`: each engine's rate search, as JSON and then as one table."""
    searches = [
        measure.rate_search(cflags, brake=not args.steady, lowest=args.lowest)
        for cflags in _engines(args)
    ]
    command = f"python bench/firmware.py --rates{_flags(args)}"
    print(json.dumps({"command": command, "searches": searches}, indent=1))
    print("\n".join([command, "", *acceptance.rates_table(searches)]))


def _isr_profile(quick: bool) -> dict[str, Any]:
    """The step interrupt's worst and mean cycles over the demo stream, and the stack's
    high-water mark after it."""
    demo = measure.within_rate(demo_stream(60 if quick else 200, seed=4), measure.advertised_rate())
    s, _, ok, _ = measure.stream("avr", demo, profile=True)
    return {
        "isr_worst_cycles": s["isr_profiled_max_cycles"],
        "isr_worst_us": round(s["isr_profiled_max_cycles"] / 16, 2),
        "isr_mean_cycles": s["isr_profiled_mean_cycles"],
        "isr_profile_record_exact": ok,
        "stack_free_bytes_after_demo": s.get("stack_free_bytes"),
    }


def _isr_cycles(stats: dict[str, Any]) -> float:
    """The step interrupts' cycles of a run: compare A (compare B nested in it included)
    and compare B on its own."""
    isr_cycles: float = stats["isr_profiled_mean_cycles"] * stats["isr_profiled_count"]
    return isr_cycles + stats.get("compare_b_outside_cycles", 0)


def _step_timing(top: int, quick: bool) -> list[dict[str, Any]]:
    """Step edges against the ideal trajectory, all four axes at once, and the step
    interrupt's load at each rate up to the advertised ``top``."""
    # rates over the advertised one are refused by the host (no edge logged)
    rates = (
        [top] if quick else sorted({r for r in (2_500, 5_000, 7_500, 10_000) if r < top} | {top})
    )
    sweep = []
    for rate in rates:
        log = Path(tempfile.mkdtemp()) / "steps.txt"
        batch = rates_bench.constant_batch([rate] * 4, n=200)
        s, _, ok, _ = measure.stream("avr", batch, profile=True, step_log=log)
        err = measure.step_error(log, batch)
        isr_cycles = _isr_cycles(s)
        sweep.append(
            {
                "steps_per_s_each_axis": rate,
                "step_err_vs_ideal_worst_us": err["worst_us"],
                "step_err_vs_ideal_p99_us": err["p99_us"],
                "isr_load_pct_whole_run": round(100 * (isr_cycles / max(s["cycles"], 1)), 1),
                "isr_load_pct_of_motion": round(100 * isr_cycles / (batch.ticks.sum() * 160), 1),
                "min_pulse_high_us": s["min_pulse_high_us"],
                "min_dir_setup_us": s["min_dir_setup_us"],
                "lost_steps": s["lost_steps"],
                "late_pulses": s["late_pulses"],
                "record_exact": ok,
            }
        )
    return sweep


def _print_mix_timing(top: int, quick: bool) -> list[dict[str, Any]]:
    """A print's mix: one module at a share of the advertised rate ``top``, the others at
    3/4 and 1/2 of it, the extruder at 1/10: the steps fall apart, each its own compare B."""
    mix = []
    for share in (0.6, 0.8, 1.0) if not quick else (1.0,):
        rates_mix = [int(top * share * f) for f in (1.0, 0.75, 0.5, 0.1)]
        log = Path(tempfile.mkdtemp()) / "steps.txt"
        batch = rates_bench.constant_batch(rates_mix, n=200)
        s, _, ok, _ = measure.stream("avr", batch, profile=True, step_log=log)
        err = measure.step_error(log, batch)
        mix.append(
            {
                "steps_per_s_per_axis": rates_mix,
                "step_err_vs_ideal_worst_us": err["worst_us"],
                "step_err_vs_ideal_p99_us": err["p99_us"],
                "isr_load_pct_of_motion": round(
                    100 * _isr_cycles(s) / (batch.ticks.sum() * 160), 1
                ),
                "overruns": s["overruns"],
                "late_pulses": s["late_pulses"],
                "harness_clock_slips": s.get("motion_clock_slips"),
                "record_exact": ok,
            }
        )
    return mix


def _streaming(quick: bool) -> dict[str, Any]:
    """Streaming at 1x over 250000 baud: segments of ever shorter duration (3-4 s of
    device time each), clean and with 1e-3 corruption and drop per byte; the highest rate
    streamed exact, and the rate every row is exact up to."""
    n_s = 2.0 if quick else 4.0
    stream = []
    # down to the device's shortest segment (CAPS: 40 units, one 0.4 ms step tick)
    for ticks in (200, 130, 100, 80, 65, 50, 45, 40):
        batch = measure.short_batch(ticks, int(n_s * CLOCK_HZ / ticks))
        payload, _ = encode_segments(batch, SegmentContext())
        row: dict[str, Any] = {"segment_ms": ticks / 100, "segments_per_s": CLOCK_HZ // ticks}
        row["payload_bytes_per_segment"] = round(len(payload) / len(batch), 2)
        for name, faults in (("clean", None), ("faults", measure.FAULTS)):
            s, _, ok, _ = measure.stream("avr", batch, faults=faults)
            row[f"{name}_record_exact"] = ok
            row[f"{name}_host_retransmits"] = s["host_retransmits"]
            row[f"{name}_main_loop_max_us"] = s.get("main_loop_max_us")
        stream.append(row)
    out: dict[str, Any] = {"streaming": stream}
    for name in ("clean", "faults"):
        exact = [r[f"{name}_record_exact"] for r in stream]
        out[f"segments_per_s_streamed_{name}"] = max(
            (r["segments_per_s"] for r, ok in zip(stream, exact) if ok), default=0
        )
        # every row up to this rate exact (the batches differ: 0.5 ms segments mostly
        # repeat the one before, 0.65 ms ones do not)
        upto = next((i for i, ok in enumerate(exact) if not ok), len(stream))
        out[f"segments_per_s_all_exact_up_to_{name}"] = (
            stream[upto - 1]["segments_per_s"] if upto else 0
        )
    return out


def _streaming_30_s() -> dict[str, Any]:
    """The issue's measure: 30 s of device time, 2000/s clean and 1000/s with faults."""
    sustained = {}
    for name, ticks, faults in measure.ISSUE_STREAMS:
        batch = measure.short_batch(ticks, 30 * CLOCK_HZ // ticks)
        s, _, ok, _ = measure.stream("avr", batch, faults=faults)
        sustained[name] = {
            "record_exact": ok,
            "device_s": s.get("sim_seconds"),
            "host_retransmits": s["host_retransmits"],
            "host_timeouts": s["host_timeouts"],
            # real time: the most simavr fell behind the wall clock (it then runs
            # flat out to catch up, faster than a board would)
            "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
        }
    return sustained


def _line_limit(stream: list[dict[str, Any]]) -> int:
    """The segments a second 250000 baud carries, the first streaming row's segments in
    frames of the 120-byte max_payload the AVR asks for."""
    per_seg: float = stream[0]["payload_bytes_per_segment"] * (1 + OVERHEAD / 120)
    return round(BAUD / 10 / per_seg)


def _figures(args: argparse.Namespace) -> dict[str, Any]:
    """Every section of the full run, in the order printed."""
    fig: dict[str, Any] = {
        "command": "python bench/firmware.py" + (" --quick" if args.quick else "")
    }
    fig.update(measure.size())
    fig.update(_isr_profile(args.quick))
    top = measure.advertised_rate()
    fig["advertised_max_step_rate"] = top
    fig["step_timing"] = _step_timing(top, args.quick)
    fig["step_timing_print_mix"] = _print_mix_timing(top, args.quick)
    fig.update(_streaming(args.quick))
    if not args.quick:
        fig["streaming_30_s"] = _streaming_30_s()
    # the same with print-like segments (varied deltas), at the rate the host plans for
    rate, min_ticks = measure.announced()
    fig["streaming_print_like"] = measure.print_like_streams(
        args.stream_rate or int(0.9 * rate),
        rate,
        seconds=5.0 if args.quick else 30.0,
        ladder=not args.quick,
    )
    fig["segments_per_s_line_limit_250000_baud"] = _line_limit(fig["streaming"])
    fig["heaters_off_after_watchdog_s"] = measure.heaters_off_latencies()
    fig["heaters_autotune_210_c"] = measure.heaters()
    fig["rate_search"] = measure.rate_search()
    fig["cup_on_announced_limits"] = measure.cup(rate, min_ticks)
    return fig


def main() -> int:
    args = _arguments()
    missing = avr_device.toolchain_missing()
    if missing:  # one line saying what to install, not a traceback
        raise SystemExit(f"bench/firmware.py: {missing}")
    avr_device.build()
    if args.heaters:
        command = {"command": "python bench/firmware.py --heaters"}
        print(json.dumps(command | measure.heaters(), indent=1))
    elif args.acceptance:
        print(f"python bench/firmware.py --acceptance{_flags(args)}")
        acceptance.print_acceptance(acceptance.acceptance_rows(tuple(_engines(args))))
    elif args.rates:
        _print_rates(args)
    else:
        print(json.dumps(_figures(args), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
