"""Print-like segment streams on the AVR in simavr, per build, and where the CPU goes.

    python bench/stream_rates.py [--engine] [--seconds S] [--rate R] [--ladder] [--profile]
    python bench/stream_rates.py --only-engine --limit 200000 --profile --ramps R

Issue 29's streaming acceptance (bench/firmware_measure.py's `print_like_streams`, the same
segments): print-like segments (bench/step_schedule.py: joint speeds along a curve, 97 %
of segments differ from the one before), the busiest module at ``--rate`` steps/s
(default 7,200: 90 % of the 8,000 the AVR announces), streamed at 1x over the harness's
250000-baud UART, 2,000 segments/s clean and 1,000/s with 1e-3 corruption and drop
(``--seconds`` of device time each, 30 by default). ``--engine`` measures the step
engine's build (``-DSTEP_ENGINE=1``, into firmware/build/engine-rate-N) beside the
default one. ``--ladder`` adds 500..2,500 segments/s clean, 3 s each.

``--profile`` runs one clean 2,000/s stream with the harness counting every executed
instruction (CDPR_SIM_PROFILE_ALL) and prints the functions that took them, as a share
of the run's instructions and per segment: where the main loop's and the interrupts'
time goes while segments stream (the frame receive and CRC, the two decodes, the queue
push, the plans, the step interrupts, the acknowledgements).
``--profile --ramps R`` profiles instead the print's mix from rest to R steps/s and back,
8 times (firmware_rates.ramp_batch, the ramps cut into pieces with their schedule blocks,
the link's frames grown first), the figures per ramp piece: what a piece of a ramp costs
(firmware/README.md, the step engine, "Starting from rest").

A row's verdict: the record equals the segments asked for (no underrun, no refused
segment); the host's retransmits and timeouts beside it; the line's payload bytes a
segment and what 250000 baud leaves (``line_limit_per_s``: 25,000 B/s over the bytes a
segment takes on the wire, frame overhead included).

Stop 53: the host cuts a stream's frames at 48 payload bytes (segment_feed's
STREAM_FRAME_BYTES); the engine's clean 2,000/s row then ran 30 s exact in 10 runs of 15
(main the same hour 0 of 7), its faults row 3 of 8 (main 1 of 7): docs/step-engine.md
section 10, "A frame's length against the queue's lead".

Figures (issue 29, 2026-11-29, 2 cores shared with three other sessions, load 3-5; the
busiest module at 7,200 steps/s, the others at 0.75/0.5/0.1 of it: 16,500 steps/s in
all). The line is not the limit: 4.12 payload bytes a segment (4.5 on the wire in 120-byte
frames), 250000 baud carries 5,550 segments/s of them; protocol 3.0 needs no change.
The firmware's CPU is: cycles a segment (``--profile``, simulated cycles, the main loop's
idle turns taken out), before (b1a1f21) and after this bench's changes:

| build, rate | before | after | where |
|---|---|---|---|
| default, 1,000/s (2 ticks a segment) | 13,690 | 11,150 | |
| default, 1,818/s (1 tick) | 11,650 (underruns at 0.2 s) | 7,970 | 2,000/s leaves 8,000 |
| step engine, 1,000/s | 13,030 | 10,270 | |
| step engine, 1,818/s | 13,000 (underruns) | 9,200 (underruns) | |

What went, a segment (default build): the check pass decoded every segment and the
execution decoded it again (2 x 510: now once, on receipt, into its queue slot; the
print's one-byte codes in ~100 cycles instead of the full decoder's 470); the step-rate
check took the per-axis 64-bit path for every short fast segment (910 + 560 in libgcc's
64-bit helpers: now 270). What is left at 1,818/s (default): the step interrupts ~3,700
(last_steps 1,390, wheel_take 615, compare B 535, dispatch 185, the tick ~600: stepper.c,
the steps' and ticks' cost, the same whatever the encoding), the plans 1,035
(motion_prepare_some), queueing a segment ~1,400 (enqueue_segment 580, the rate check
270, motion_store 260, the limits 120, the accounting 180), receiving it ~1,000 (staging
and its decode 400, the UART's interrupts 330, CRC 210, the rest of the frame path).
The step engine's build spends ~4,500 a segment in its interrupts (step_engine_push,
seg_chunks, each axis's end-of-chunk and compare vectors).

Clean ladders at 1x, 3 s each (`--ladder`; before -> after): default exact up to 1,250
-> 1,818-2,000 segments/s (2,000 passed 3 s in one run of three: the CPU is at ~100 %
there, and a run underruns when simavr falls behind the wall clock on the loaded
machine); step engine up to 1,250 -> 1,538-1,666. The 30 s rows (`--engine`): default
2,000/s clean underruns at 0.6-3.1 s (also at `--speedup 0.5`: the firmware's CPU, not the
host or simavr), 1,000/s with 1e-3 corruption and drop exact for 30 s in one run (968
resends, 42 timeouts) and underran at 5 s in another with simavr 380 ms behind the wall
(4-11 s before); step engine 2,000/s underruns at 0.3 s, 1,000/s with the faults at
6.5-10.3 s. Also: the soft-limit check's variable shift loop (machine.c, 119 -> 44 cycles
without limits).

Then (stream30, default build, 1,818/s, ``--profile --ticks 55 --seconds 4``, the turns
now counted by watchdog_canary_ok, base 478e442 measured the same way): the segments'
work 8,300 -> 8,030 cycles a segment; last_steps 1,391 -> 1,093 (its last slot once, no
variable shift per axis, the positions in a loop of their own: the one loop spilled its
pointers), the watchdog record's CRC-16 once a change (check_of 113 -> 80), and
save_progress's copy of the counters only after a tick or a main-loop change (an idle
turn's fifth). 30 s clean 2,000/s rows: 1x on the loaded machine, base 2.9 s then
underrun; this, seven runs: exact for 30 s twice (simavr 33 ms behind the wall at most in
one, 1.96 s in the other) and underruns at 12.0, 5.1, 6.0, 15.0, 12.3 s (simavr 20-375 ms
behind); 1,000/s with 1e-3 corruption and drop exact for 30 s (801 resends, 31
timeouts). ``--speedup 0.5`` exact for 30 s, twice, and so is the base (once, this day):
at 2,000/s the firmware's CPU keeps up when the host and simavr do, and the 1x underruns
follow the machine's load.

Stop 52: some of those underruns were the host's own: a full garbage collection (20-25 ms)
inside the feed. The stream now runs inside ``quiet_collection()`` (cdprhost/link/
collector.py). Three 30 s runs each, idle, same hour: the default build's 2,000/s exact 3 of
3; the step engine at 1,613/s (``--ticks 62``) exact 3 of 3 (before 1 of 3), at 2,000/s dry
at 0.4-5.4 s (before 1.0-2.9 s), with the main-loop turn's fixed work 2,740 -> 1,574 cycles
idle; 1,000/s with 1e-3 corruption and drop on the engine exact in 2 of 7 runs (the build
before: 1 of 5; stop 51 had 3 of 3): its 64 ms of queue against the link's go-back-N
resends. ``--speedup`` below 1 is no longer a clean test of the firmware: the host's
timeouts run in wall time, so the device's slower replies look lost (retransmissions,
halved windows) and the stream runs dry sooner.
"""

from __future__ import annotations

import argparse
import bisect
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import firmware_measure as measure
import firmware_rates as rates_bench

from cdprhost.link import LinkError, open_link
from cdprhost.sim.avr_device import Relay
from firmware_protocol.device.faults import FaultSpec
from firmware_protocol.framing import OVERHEAD
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segments import SegmentBatch, SegmentContext, encode_segments
from firmware_protocol.streams import expected_record

CLOCK_HZ = 100_000
LINE_BYTES_PER_S = 25_000  # 250000 baud, 10 bits a byte
MAX_PAYLOAD = 120  # the AVR's IDENT max_payload


def _build(engine: bool, limit: int) -> rates_bench.Build:
    if not engine:
        return rates_bench.default_build()
    return rates_bench.variant(limit, rates_bench.ENGINE_CFLAGS)


def stream(
    build: rates_bench.Build,
    batch: SegmentBatch,
    *,
    faults: str | None = None,
    env_extra: dict[str, str] | None = None,
    speedup: float = 1.0,
    warm: bool = False,
) -> dict[str, Any]:
    """Stream ``batch`` at 1x to the harness running ``build`` (through a lossy relay
    with ``faults``): the harness's figures, the host's counters and the verdict.
    ``warm``: the link's frames grown to full length first (firmware_rates.warm_link), so
    a ramp's schedule blocks go with it."""
    tmp = Path(tempfile.mkdtemp())
    env = dict(os.environ, **(env_extra or {}))
    cmd = [str(build.harness), str(build.elf), "--speedup", f"{speedup:g}"]
    cmd += ["--record", str(tmp / "record.jsonl"), "--stats", str(tmp / "stats.json")]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    assert proc.stdout is not None
    path = proc.stdout.readline().strip()
    relay = Relay(path, FaultSpec.parse(faults)) if faults else None
    stop = threading.Event()

    def pump() -> None:
        while relay and not stop.is_set():
            relay.step(0.002)

    pumper = threading.Thread(target=pump, daemon=True)
    pumper.start()
    error = ""
    t0 = time.monotonic()
    try:
        link = open_link(relay.path if relay else path)
        try:
            if warm:
                rates_bench.warm_link(link)
            link.queue_segments(batch)
            link.wait_idle(600)
        except LinkError as e:  # an underrun or another device fault
            error = str(e)[:160]
        finally:
            retx, timeouts = link.counters.retransmits, link.counters.timeouts
            link.close()
    finally:
        wall = time.monotonic() - t0
        stop.set()
        pumper.join(5)
        if relay:
            relay.close()
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    rows = [json.loads(x) for x in (tmp / "record.jsonl").read_text().splitlines() if x.strip()]
    stats = tmp / "stats.json"
    s = json.loads(stats.read_text()) if stats.exists() else {}
    shutil.rmtree(tmp, ignore_errors=True)  # (read: a run's folder left behind filled /tmp)
    return {
        "record_exact": not error and rows == expected_record(batch),
        "error": error,
        "segments_done": len(rows),
        "device_s": s.get("sim_seconds"),
        "wall_s": round(wall, 1),
        "host_retransmits": retx,
        "host_timeouts": timeouts,
        "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
        "main_loop_max_us": s.get("main_loop_max_us"),
    }


def line_figures(batch: SegmentBatch) -> dict[str, float]:
    """Payload bytes a segment and the segments/s 250000 baud carries at that size (in
    frames of the AVR's 120-byte max_payload)."""
    payload, _ = encode_segments(batch, SegmentContext())
    per_seg = len(payload) / len(batch)
    wire = per_seg * (1 + OVERHEAD / MAX_PAYLOAD)
    return {
        "payload_bytes_per_segment": round(per_seg, 2),
        "wire_bytes_per_segment": round(wire, 2),
        "line_limit_per_s": round(LINE_BYTES_PER_S / wire),
    }


def _symbols(elf: Path) -> tuple[list[int], list[str]]:
    out = subprocess.run(
        ["avr-nm", "-n", "-C", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    addrs, names = [], []
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1].lower() == "t":
            addrs.append(int(parts[0], 16))
            names.append(parts[2])
    return addrs, names


def _cycles_by_function(elf: Path, hist: Path) -> dict[str, int]:
    """The harness's cycles per address (CDPR_SIM_PC_HIST) summed per function."""
    addrs, names = _symbols(elf)
    per: dict[str, int] = defaultdict(int)
    for line in hist.read_text().splitlines():
        pc, n = line.split()
        i = bisect.bisect_right(addrs, int(pc, 16)) - 1
        per[names[i] if i >= 0 else "?"] += int(n)
    return per


def _idle_session(build: rates_bench.Build, env_extra: dict[str, str], seconds: float) -> None:
    """A session open on the harness running ``build`` for ``seconds``, nothing sent."""
    cmd = [str(build.harness), str(build.elf), "--speedup", "1"]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=dict(os.environ, **env_extra),
    )
    assert proc.stdout is not None
    try:
        link = open_link(proc.stdout.readline().strip())
        time.sleep(seconds)
        link.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)


#: a function the main loop runs once a turn whatever it has to do, at the same cost (the
#: stack canary's check): the measure of how many turns a run took
TURN_MARK = "watchdog_canary_ok"


def profile(
    build: rates_bench.Build,
    batch: SegmentBatch,
    top: int = 30,
    warm: bool = False,
    per: int | None = None,
) -> dict[str, Any]:
    """Where the cycles go per segment: one stream with the harness counting every
    executed instruction's cycles by address (CDPR_SIM_PROFILE_ALL), summed per function,
    less the main loop's turns. The turns are measured on an idle session first (every
    function's cycles per turn, TURN_MARK counting the turns) and taken out at the
    stream's count of turns: what is left is the work the segments cost (the stream's
    first moments, before its first segment, count as turns). The top ``top`` functions
    by that work, per segment (or per ``per`` of the stream's segments: its ramp pieces).
    ``warm``: as stream's."""
    tmp = Path(tempfile.mkdtemp())
    env = {"CDPR_SIM_PROFILE_ALL": "1", "CDPR_SIM_PC_HIST": str(tmp / "idle.txt")}
    _idle_session(build, env, 2.0)
    idle = _cycles_by_function(build.elf, tmp / "idle.txt")
    env["CDPR_SIM_PC_HIST"] = str(tmp / "stream.txt")
    r = stream(build, batch, env_extra=env, warm=warm)
    load = _cycles_by_function(build.elf, tmp / "stream.txt")
    shutil.rmtree(tmp, ignore_errors=True)
    turns = load.get(TURN_MARK, 0) / max(idle.get(TURN_MARK, 0), 1)  # in idle sessions
    work = {k: v - turns * idle.get(k, 0) for k, v in load.items()}
    total = sum(load.values())
    done = max(per or int(r["segments_done"]), 1)
    each = "ramp_piece" if per else "segment"
    rows = sorted(work.items(), key=lambda kv: -kv[1])[:top]
    return {
        "run": r,
        f"cycles_per_{each}": round(total / done),
        "turns_share_pct": round(100 * turns * sum(idle.values()) / total, 1),
        f"work_cycles_per_{each}": round(sum(work.values()) / done),
        # name: the segments' work in it, cycles per segment (or ramp piece)
        "functions": [f"{n}: {c / done:.0f}" for n, c in rows],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--engine", action="store_true", help="the step engine's build too")
    ap.add_argument("--only-engine", action="store_true", help="the step engine's build only")
    ap.add_argument("--seconds", type=float, default=30.0, help="device time of a stream")
    ap.add_argument("--rate", type=int, default=7_200, help="the busiest module's steps/s")
    ap.add_argument("--limit", type=int, default=8_000, help="the build's announced steps/s")
    ap.add_argument("--ladder", action="store_true", help="500..2500 segments/s, 3 s each")
    ap.add_argument("--profile", action="store_true", help="where the instructions go")
    ap.add_argument("--ticks", type=int, default=50, help="--profile: segment length (units)")
    ap.add_argument(
        "--ramps",
        type=int,
        default=0,
        help="--profile: instead of the print-like stream, the print's mix from rest to R "
        "steps/s and back 8 times (firmware_rates.ramp_batch), the ramps cut into pieces with "
        "their schedule blocks: where a ramp piece's cycles go",
    )
    ap.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        help="device time against wall time (0.5: the host has twice the time, the "
        "device's CPU the same: a run that passes at 0.5 and fails at 1 is limited by the "
        "host or by simavr keeping up, not by the firmware)",
    )
    ap.add_argument("--no-faults", action="store_true", help="the clean 2,000/s stream only")
    args = ap.parse_args()
    engines = [True] if args.only_engine else [False, True] if args.engine else [False]
    out: dict[str, Any] = {"busiest_module_steps_per_s": args.rate}
    for engine in engines:
        build = _build(engine, args.limit)
        name = "step engine" if engine else "default"
        fig: dict[str, Any] = {}
        if args.profile and args.ramps:
            mix = rates_bench.rates_of("a print's mix", args.ramps)
            batch = rates_bench.cut_for_blocks(rates_bench.ramp_batch(mix, cycles=8))
            pieces = int(np.count_nonzero(batch.ramps != RAMP_CONSTANT))
            # the figures per ramp piece, not per segment
            fig[f"profile_ramps_to_{args.ramps}_per_ramp_piece"] = {
                "ramp_pieces": pieces,
                **profile(build, batch, top=60, warm=True, per=pieces),
            }
        elif args.profile:
            batch = measure.print_like_batch(args.rate, args.ticks, args.seconds, args.limit)
            fig[f"profile_{CLOCK_HZ // args.ticks}_per_s"] = profile(build, batch)
        else:
            if args.ladder:
                fig["ladder_clean_3_s"] = []
                for ticks in (200, 100, 80, 65, 50, 40):
                    batch = measure.print_like_batch(args.rate, ticks, 3.0, args.limit)
                    r = stream(build, batch, speedup=args.speedup)
                    fig["ladder_clean_3_s"].append(
                        {"segments_per_s": CLOCK_HZ // ticks, **line_figures(batch), **r}
                    )
            runs: list[tuple[str, int, str | None]] = [("clean_2000_per_s", 50, None)]
            if not args.no_faults:
                runs.append(("faults_1000_per_s", 100, "corrupt=0.001,drop=0.001"))
            for row, ticks, faults in runs:
                batch = measure.print_like_batch(args.rate, ticks, args.seconds, args.limit)
                r = stream(build, batch, faults=faults, speedup=args.speedup)
                deltas_differ = np.any(np.diff(batch.deltas, axis=0) != 0, axis=1).mean()
                fig[row] = {
                    "segments": len(batch),
                    "deltas_differ_pct": round(100 * float(deltas_differ), 1),
                    **line_figures(batch),
                    **r,
                }
        out[name] = fig
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
