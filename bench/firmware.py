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
- heaters off after the host's silence, in each device state (idle heating, moving,
  faulted after an UNDERRUN, waiting for a heater): the time from the host's last byte to
  the heater pin going low, minus the watchdog time (500 ms).
- heaters on the shared plant (firmware_protocol/device/thermal_plant.py): a cold relay
  autotune of the hotend at 210 C, 3 cycles, on each device (the Python device at 50x,
  the AVR as fast as simavr runs): its gains, the relay period 2 kp / ki, the device
  seconds it took, and the AVR's gains against the Python device's (`--heaters` runs
  only these rows).

- the highest step rate per configuration (issue 29; bench/firmware_rates.py), in
  simulated time: one module alone; three modules in step; three out of step with the
  extruder running (R, 0.997 R, 0.993 R, at least a step a segment apart, the extruder at
  0.1 R: their edges drift across each other); a print's mix (R, 0.75 R, 0.5 R, 0.1 R).
  For each, R is bisected to 500 steps/s and confirmed on 3 runs: every edge within
  10 us of its ideal time, p99 within 5 us, every edge there, no overrun, no lost or late
  step, no clock slip, the record exact. A point is 30 constant-speed segments of 10 ms
  (300 ms of device time) on a build announcing 200,000 steps/s (the MAX_STEP_RATE
  override: `make -C firmware BUILD=build/rate-200000 EXTRA_CFLAGS=-DMAX_STEP_RATE=200000UL
  sim`, beside the default build the tests use). Reported: R, its worst and p99 edge
  error, the step interrupts' share of the motion's cycles (the idle ticks outside
  motion taken out at the share measured with nothing moving), the lowest rate that
  failed and why; then the print's mix speeding up from rest to its R and back.
- streaming with print-like segments: bench/step_schedule.py's stream (joint speeds
  varying along a curve: 97 % of segments differ from the one before), back and forth
  within the travel, the busiest module at 90 % of the announced rate (the host's plan;
  `--stream-rate` for another): 500..2000 segments/s clean for 3 s each, then the issue's
  2000/s clean and 1000/s with the faults for 30 s of device time.
- the cup (`examples/example.gcode`, `paper-prototype`) on the limits the firmware
  announces (IDENT, CAPS) against the profile's own: bench/board_estimate.py (the Python
  device announcing them; the AVR's own print of it takes half an hour of real time).
- `--acceptance`: exactly the issue's acceptance rows (the rates at their figures on a
  build announcing them, the cup, the estimate, the 30 s streams, heaters off, flash,
  RAM and stack), pass or fail, as a table for the closing note.

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
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import firmware_rates as rates_bench
from step_schedule import print_like

from cdprhost.link import LinkError, open_link
from cdprhost.sim import avr_device
from firmware_protocol.framing import OVERHEAD
from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_TO_REST, ramp_share
from firmware_protocol.segments import SegmentBatch, SegmentContext, encode_segments
from firmware_protocol.streams import demo_stream, expected_record

CLOCK_HZ = 100_000
BAUD = 250_000


def _stream(
    kind: str,
    batch: SegmentBatch,
    *,
    speedup: float = 1.0,
    profile: bool = False,
    faults: str | None = None,
    step_log: Path | None = None,
) -> tuple[dict[str, Any], list[dict[str, Any]], bool, float]:
    """Stream ``batch`` to a ``sim-device --firmware kind``: (harness stats, record, ok, wall).
    The stats gain the host's ``host_retransmits`` and ``host_timeouts``."""
    tmp = Path(tempfile.mkdtemp())
    stats, record = tmp / "stats.json", tmp / "record.jsonl"
    env = dict(os.environ, **{avr_device.STATS_ENV: str(stats)})
    if profile:
        env["CDPR_SIM_PROFILE_ISR"] = "1"
    if step_log is not None:
        env["CDPR_SIM_STEP_LOG"] = str(step_log)
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", kind]
    cmd += ["--speedup", f"{speedup:g}", "--record", str(record)]
    if faults:
        cmd += ["--faults", faults]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    assert proc.stdout is not None
    path = proc.stdout.readline().strip()
    ok = True
    retx = timeouts = -1
    t0 = time.monotonic()
    try:
        link = open_link(path)
        try:
            link.queue_segments(batch)
            link.wait_idle(600)
        except LinkError:  # an underrun or another device fault: this rate failed
            ok = False
        finally:
            retx, timeouts = link.counters.retransmits, link.counters.timeouts
            link.close()
    finally:
        wall = time.monotonic() - t0
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    rows = [json.loads(x) for x in record.read_text().splitlines() if x.strip()]
    s = json.loads(stats.read_text()) if stats.exists() else {}
    s["host_retransmits"], s["host_timeouts"] = retx, timeouts
    return s, rows, ok and rows == expected_record(batch), wall


def _ideal_step_times(batch: SegmentBatch) -> list[np.ndarray]:
    """Per axis, the exact time (clock units from the start of motion) of every step of
    ``batch`` on its segments' profiles (PROTOCOL.md 5.1: step j where |n| p crosses
    j - 1/2), in order."""
    starts = np.concatenate([[0], np.cumsum(batch.ticks)[:-1]]).astype(np.float64)
    r_all = ramp_share(batch.ramps)
    out: list[list[np.ndarray]] = [[], [], [], []]
    for i in range(len(batch)):
        r, d = float(r_all[i]), float(batch.ticks[i])
        for k in range(4):
            n = abs(int(batch.deltas[i, k]))
            if not n:
                continue
            x = (np.arange(1, n + 1) - 0.5) / n
            tau = x / (r + np.sqrt(r * r + (1 - 2 * r) * x))
            out[k].append(starts[i] + d * tau)
    return [np.concatenate(a) if a else np.zeros(0) for a in out]


def _step_error(log: Path, batch: SegmentBatch) -> dict[str, float]:
    """Every rising step edge the harness logged against its ideal time: worst and 99th
    percentile of |error| in us (1 clock unit = 10 us, 16 cycles = 1 us)."""
    rows = np.loadtxt(log, dtype=np.int64, ndmin=2)
    ideal = _ideal_step_times(batch)
    errs = []
    for k in range(4):
        got = rows[rows[:, 0] == k, 1] / 16.0  # us on the motion clock
        want = ideal[k] * 1e6 / CLOCK_HZ
        m = min(len(got), len(want))
        if m:
            errs.append(got[:m] - want[:m])
    e = np.abs(np.concatenate(errs)) if errs else np.zeros(1)
    return {"worst_us": round(float(e.max()), 2), "p99_us": round(float(np.percentile(e, 99)), 2)}


def _advertised_rate() -> int:
    """The firmware's MAX_STEP_RATE (steps/s on any one axis, IDENT max_step_rate)."""
    text = (avr_device.FIRMWARE_DIR / "src" / "config.h").read_text()
    m = re.search(r"#define MAX_STEP_RATE (\d+)UL", text)
    assert m, "MAX_STEP_RATE not found in firmware/src/config.h"
    return int(m.group(1))


def _rate_batch(rate: int | list[int], n: int = 40, ticks: int = 1000) -> SegmentBatch:
    """``n`` segments at ``rate`` steps/s on all four axes (or one rate per axis), back
    and forth; the last one brakes to rest from the same rate (half the distance)."""
    rates = np.array(rate if isinstance(rate, list) else [rate] * 4)
    d = rates * ticks // CLOCK_HZ
    sign = np.where((np.arange(n) // 4) % 2 == 0, 1, -1)
    deltas = np.outer(sign, d)
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
        ["avr-size", str(avr_device.BOARD_ELF)], capture_output=True, text=True, check=True
    ).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    return {
        "flash_bytes": text + data,
        "flash_of_256k_pct": round(100 * (text + data) / 262_144, 1),
        "ram_static_bytes": data + bss,
        "ram_of_8k_pct": round(100 * (data + bss) / 8192, 1),
    }


def _heaters_off_latency(state: str, watchdog_ms: int = 500) -> float:
    """Seconds from the host's last byte to the heater pin going low, minus the watchdog
    time, with the device in ``state`` when the host falls silent (wall time: the link's
    clock in the harness)."""
    from firmware_protocol.messages import Configure, Flush, Segment, SetHeater, WaitHeater
    from tests.conformance.device import RawHost, start

    tmp = Path(tempfile.mkdtemp())
    dev = start("avr", tmp, "--speedup", "1")
    h = RawHost(dev.path)
    try:
        h.hello()
        h.send(Configure(watchdog_ms=watchdog_ms, start_ticks=100_000, flow_ticks=12_500))
        h.send(SetHeater(0, 1500))
        if state == "moving":
            h.send(Segment(ticks=1_000_000, deltas=(2000, 0, 0, 0), ramp=RAMP_TO_REST), Flush())
        elif state == "faulted (underrun)":
            h.send(Segment(ticks=2000, deltas=(40, 0, 0, 0), ramp=RAMP_CONSTANT), Flush())
        elif state == "waiting (WAIT_HEATER)":
            h.send(WaitHeater(0, 1))
        h.pump(0.5)
        h.keepalive = 0  # the host dies: nothing more is sent
        end = time.monotonic() + 3 * watchdog_ms / 1000
        while time.monotonic() < end:
            h.pump(0.05)
    finally:
        h.close()
        dev.stop()
    return round(dev.stats()["heater_on_silence_max_s"] - watchdog_ms / 1000, 4)


def _autotune(kind: str) -> dict[str, Any]:
    """A cold relay autotune of the hotend at 210 C, 3 cycles: gains, period, device time."""
    from firmware_protocol.messages import Autotune, Error, Event, EventCode
    from tests.conformance.device import RawHost, start

    dev = start(kind, Path(tempfile.mkdtemp()), "--speedup", "50")
    h = RawHost(dev.path)
    try:
        h.hello()
        t0 = h.status().clock / CLOCK_HZ
        h.send(Autotune(0, 2100, 3))
        ev = h.wait_for(
            lambda: h.of(Event, code=EventCode.AUTOTUNE_DONE) or h.of(Error),
            timeout=1800,
            what="AUTOTUNE_DONE",
        )
        device_s = h.status().clock / CLOCK_HZ - t0
    finally:
        h.close()
        dev.stop()
    if not isinstance(ev, Event):
        return {"error": str(ev)}
    kp, ki, kd = (v / 1000 for v in ev.values[1:])
    return {
        "kp": kp,
        "ki": ki,
        "kd": kd,
        "period_s": round(2 * kp / ki, 1),
        "device_s": round(device_s, 1),
    }


def _heaters() -> dict[str, Any]:
    out = {kind: _autotune(kind) for kind in ("python", "avr")}
    py, avr = out["python"], out["avr"]
    if "kp" in py and "kp" in avr:
        out["avr_vs_python_pct"] = {
            k: round(100 * (avr[k] - py[k]) / py[k], 1) for k in ("kp", "ki", "kd", "period_s")
        }
    return out


def _announced() -> tuple[int, int]:
    """What the default build announces: IDENT max_step_rate and CAPS min_segment_ticks."""
    with rates_bench.harness(rates_bench.default_build(), profile=False) as (link, _):
        assert link.identity is not None
        caps = link.caps
        return link.identity.max_step_rate, caps.min_segment_ticks if caps else 1


def _rate_search(
    cflags: str = "", speedup: float = 4.0, brake: bool = True, lowest: int = 1_000
) -> dict[str, Any]:
    """Per configuration, the highest R with every edge within 10 us of its ideal time,
    p99 within 5 us, no overrun, no lost or late step, the record exact (firmware_rates.py:
    constant-speed segments on a build announcing up to 200,000 steps/s, with the build
    options ``cflags``: "" the default engine, ``ENGINE_CFLAGS`` the step engine); the step
    interrupts' load there; then the print's mix speeding up from rest to its R and back.
    Without ``brake`` the points stop (a segment at rest) instead of braking on a ramp;
    ``lowest``: where the search starts (a configuration failing there has no R)."""
    build = rates_bench.variant(max(rates_bench.CEILINGS.values()), cflags)
    idle = rates_bench.idle_isr_share(build)
    out: dict[str, Any] = {
        "engine": build.engine,
        "build": f"firmware/{build.elf.parent.relative_to(avr_device.FIRMWARE_DIR)}",
        "isr_idle_share_pct": round(100 * idle, 1),
        "points_end": "braking on a ramp" if brake else "with a stop",
    }
    rows = []
    for config in rates_bench.CONFIGS:
        r = rates_bench.highest_rate(build, config, lo=lowest, speedup=speedup, brake=brake)
        at = r.pop("at", None)
        if at is not None:
            r["isr_load_pct_of_motion"] = rates_bench.isr_load_pct(at, idle)
            r["steps_per_s_per_axis"] = at["steps_per_s"]
        rows.append(r)
    out["highest_rate"] = rows
    mix_rate = rows[-1].get("rate")
    if mix_rate:
        ramp = rates_bench.run_batch(
            build,
            rates_bench.ramp_batch(rates_bench.rates_of("a print's mix", mix_rate)),
            speedup=speedup,
        )
        out["print_mix_with_ramps_at_its_rate"] = {
            "rate": mix_rate,
            "passed": ramp["passed"],
            "worst_us": ramp["worst_us"],
            "p99_us": ramp["p99_us"],
            "isr_load_pct_of_motion": rates_bench.isr_load_pct(ramp, idle),
            "fail_reason": rates_bench.fail_reason(ramp),
        }
    return out


def _engines(args: argparse.Namespace) -> list[str]:
    """The build options of each engine to measure: the default engine (the baseline)
    first, then the step engine (``--engine``) and ``--cflags``'s build."""
    out = [""]
    if args.engine:
        out.append(rates_bench.ENGINE_CFLAGS)
    if args.cflags:
        out.append(args.cflags)
    return list(dict.fromkeys(out))


def _rates_table(searches: list[dict[str, Any]]) -> list[str]:
    """The rate searches of one run as one markdown table, engine beside engine."""
    head = ("configuration", "engine", "highest R (steps/s)", "worst / p99 edge at R")
    head += ("ISR load at R", "first fail")
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for i, config in enumerate(rates_bench.CONFIGS):
        for search in searches:
            r = search["highest_rate"][i]
            rate = f"{r['rate']:,}" if r.get("rate") else "none"
            edge = f"{r['worst_us']} / {r['p99_us']} us" if "worst_us" in r else ""
            load = f"{r['isr_load_pct_of_motion']} %" if "isr_load_pct_of_motion" in r else ""
            fail = f"{r['lowest_fail']:,}: {r['fail_reason']}" if "lowest_fail" in r else "none"
            lines.append(f"| {config} | {search['engine']} | {rate} | {edge} | {load} | {fail} |")
    for search in searches:
        ramp = search.get("print_mix_with_ramps_at_its_rate")
        if ramp:
            verdict = "passes" if ramp["passed"] else f"fails: {ramp['fail_reason']}"
            lines.append(
                f"| the mix with ramps from rest to {ramp['rate']:,} and back | "
                f"{search['engine']} | {verdict} | {ramp['worst_us']} / {ramp['p99_us']} us"
                f" | {ramp['isr_load_pct_of_motion']} % | |"
            )
    idle = ", ".join(f"{s['engine']} {s['isr_idle_share_pct']} %" for s in searches)
    lines += ["", f"The step interrupts' share of the CPU with nothing moving: {idle}."]
    return lines


def _print_like_batch(rate: int, ticks: int, seconds: float, limit: int) -> SegmentBatch:
    """bench/step_schedule.py's print-like stream (every joint speed varying along a curve,
    the deltas differ segment to segment), the busiest module at ``rate``, back and forth:
    each block of at most 6,000 steps on the busiest module is followed by its mirror
    (the same segments backwards, reversed), so the modules stay inside their travel; no
    segment over the device's ``limit`` steps/s; the first and last segment (from and to
    rest: their peak is twice their mean) at half their steps."""
    b = print_like(seconds, rate=float(rate), ticks=ticks)
    most = limit * ticks // CLOCK_HZ
    deltas = np.clip(b.deltas, -most, most)
    block = max(1, min(len(deltas) // 2, int(6_000 * CLOCK_HZ / (rate * ticks))))
    out = []
    for i in range(0, len(deltas), 2 * block):
        part = deltas[i : i + block]
        out += [part, -part[::-1]]
    deltas = np.concatenate(out)[: len(deltas)]
    deltas[[0, -1]] = np.trunc(deltas[[0, -1]] / 2).astype(np.int64)
    return SegmentBatch(b.ticks, deltas, b.ramps)


def _print_like_streams(
    rate: int, limit: int, seconds: float = 30.0, ladder: bool = False
) -> dict[str, Any]:
    """The issue's streaming measure with print-like segments, at 1x over 250000 baud:
    2000 segments/s clean and 1000/s with 1e-3 corruption and drop, ``seconds`` of device
    time each, the busiest module at ``rate`` steps/s; with ``ladder``, first 500..2000
    segments/s clean, 3 s each (where the record stops being exact)."""
    out: dict[str, Any] = {"busiest_module_steps_per_s": rate}
    if ladder:
        steps = []
        for ticks in (200, 100, 80, 65, 50):
            s, _, ok, _ = _stream("avr", _print_like_batch(rate, ticks, 3.0, limit))
            steps.append(
                {
                    "segments_per_s": CLOCK_HZ // ticks,
                    "record_exact": ok,
                    "device_s": s.get("sim_seconds"),
                    "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
                }
            )
        out["ladder_clean_3_s"] = steps
    for name, ticks, faults in (
        ("clean_2000_per_s", 50, None),
        ("faults_1000_per_s", 100, "corrupt=0.001,drop=0.001"),
    ):
        batch = _print_like_batch(rate, ticks, seconds, limit)
        s, _, ok, _ = _stream("avr", batch, faults=faults)
        payload, _ = encode_segments(batch, SegmentContext())
        out[name] = {
            "record_exact": ok,
            "segments": len(batch),
            "payload_bytes_per_segment": round(len(payload) / len(batch), 2),
            # segments whose deltas differ from the one before (a repeat costs a byte)
            "deltas_differ_pct": round(
                100 * float(np.any(np.diff(batch.deltas, axis=0) != 0, axis=1).mean()), 1
            ),
            "device_s": s.get("sim_seconds"),
            "host_retransmits": s["host_retransmits"],
            "host_timeouts": s["host_timeouts"],
            "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
        }
    return out


def _cup(rate: int, min_ticks: int) -> dict[str, Any]:
    """The cup's print time on the board's announced limits against the profile's own
    (bench/board_estimate.py: the Python device announcing the AVR's limits)."""
    script = Path(__file__).resolve().parent / "board_estimate.py"
    cmd = [sys.executable, str(script), "--rate", str(rate), "--min-ticks", str(min_ticks)]
    out = subprocess.run(
        cmd, capture_output=True, text=True, check=True, cwd=Path(__file__).resolve().parents[1]
    ).stdout
    fig = json.loads(out)
    plain = fig["estimate_profile_limits_s"]
    return {
        "board": fig["board"],
        "printed_on_board_limits_s": fig["printed_s"],
        "planned_without_cap_s": plain,
        "board_slower_pct": round(100 * (fig["printed_s"] - plain) / plain, 2),
        "estimate_with_board_s": fig["estimate_s"],
        "estimate_error_pct": fig["estimate_error_pct"],
        "board_message": fig["board_message"],
    }


def _stack_free() -> int | None:
    """The static worst-case stack's free bytes (firmware/tools/stack_usage.py)."""
    tool = avr_device.FIRMWARE_DIR / "tools" / "stack_usage.py"
    out = subprocess.run(
        [sys.executable, str(tool)], capture_output=True, text=True, check=False
    ).stdout
    m = re.search(r"(-?\d+) B free", out)
    return int(m.group(1)) if m else None


def _acceptance(engines: tuple[str, ...] = ("",)) -> list[tuple[str, str, str, bool | None]]:
    """The issue's acceptance rows: (what, the issue's figure, measured, passed); the rate
    rows for each engine of ``engines`` (build options: "" the default engine)."""
    rows: list[tuple[str, str, str, bool | None]] = []
    for config, rate in (
        ("a print's mix", 30_000),
        ("three modules out of step, extruder running", 33_000),
        ("one module alone", 100_000),
    ):
        rates = rates_bench.rates_of(config, rate)
        for cflags in engines:
            build = rates_bench.variant(max(rates), cflags)
            p = rates_bench.run_batch(build, rates_bench.constant_batch(rates))
            got = f"worst {p['worst_us']} us, p99 {p['p99_us']} us"
            if not p["passed"]:
                got += f"; {rates_bench.fail_reason(p)}"
            what = f"{config} at R = {rate:,}" + (f" ({build.engine})" if len(engines) > 1 else "")
            rows.append((what, "worst <= 10 us, p99 <= 5 us, clean", got, p["passed"]))
    rate, min_ticks = _announced()
    cup = _cup(rate, min_ticks)
    rows.append(
        (
            f"cup on the AVR's limits ({rate}/s, {min_ticks} ticks) vs no cap",
            "<= +1 %",
            f"{cup['board_slower_pct']:+.2f} %",
            cup["board_slower_pct"] <= 1.0,
        )
    )
    rows.append(
        (
            "check/print estimate vs the print on the board's limits",
            "within 1 %",
            f"{cup['estimate_error_pct']:+.2f} %",
            abs(cup["estimate_error_pct"]) <= 1.0,
        )
    )
    rows.append(
        (
            "the cup printed on the AVR in simavr equals the Python device's",
            "equal",
            "not run (about 30 min of real time; bench/board_estimate.py's note)",
            None,
        )
    )
    streams = _print_like_streams(int(0.9 * rate), rate)
    for name, what in (
        ("clean_2000_per_s", "2,000 segments/s clean, 30 s"),
        ("faults_1000_per_s", "1,000 segments/s, 1e-3 corruption and drop, 30 s"),
    ):
        r = streams[name]
        rows.append(
            (
                f"{what}, print-like at {streams['busiest_module_steps_per_s']}/s",
                "record exact",
                f"exact {r['record_exact']}, {r['host_retransmits']} retx",
                bool(r["record_exact"]),
            )
        )
    offs = {
        state: _heaters_off_latency(state)
        for state in ("idle, heating", "moving", "faulted (underrun)", "waiting (WAIT_HEATER)")
    }
    worst = max(offs.values())
    rows.append(
        (
            "heaters off after the watchdog (worst of 4 states)",
            "<= 0.1 s",
            f"{worst:.3f} s",
            worst <= 0.1,
        )
    )
    size, free = _size(), _stack_free()
    rows.append(
        (
            "flash, RAM, static worst-case stack",
            ">= 64 B stack free",
            f"flash {size['flash_bytes']} B, RAM {size['ram_static_bytes']} B, stack {free} B free",
            free is not None and free >= 64,
        )
    )
    return rows


def _print_acceptance(rows: list[tuple[str, str, str, bool | None]]) -> None:
    print("| acceptance row | issue | measured | |")
    print("|---|---|---|---|")
    for what, want, got, ok in rows:
        mark = "n/a" if ok is None else ("pass" if ok else "FAIL")
        print(f"| {what} | {want} | {got} | {mark} |")


def main() -> int:
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
    args = ap.parse_args()
    missing = avr_device.toolchain_missing()
    if missing:  # one line saying what to install, not a traceback
        raise SystemExit(f"bench/firmware.py: {missing}")
    avr_device.build()
    if args.heaters:
        print(json.dumps({"command": "python bench/firmware.py --heaters"} | _heaters(), indent=1))
        return 0
    engines = _engines(args)
    flags = " --engine" * args.engine + " --steady" * args.steady
    flags += f" --lowest {args.lowest}" if args.lowest != 1_000 else ""
    flags += f" --cflags '{args.cflags}'" if args.cflags else ""
    if args.acceptance:
        print(f"python bench/firmware.py --acceptance{flags}")
        _print_acceptance(_acceptance(tuple(engines)))
        return 0
    if args.rates:
        searches = [
            _rate_search(cflags, brake=not args.steady, lowest=args.lowest) for cflags in engines
        ]
        command = f"python bench/firmware.py --rates{flags}"
        print(json.dumps({"command": command, "searches": searches}, indent=1))
        print("\n".join([command, "", *_rates_table(searches)]))
        return 0
    fig: dict[str, Any] = {
        "command": "python bench/firmware.py" + (" --quick" if args.quick else "")
    }
    fig.update(_size())

    demo = demo_stream(60 if args.quick else 200, seed=4)  # within 8000 steps/s
    s, _, ok, _ = _stream("avr", demo, profile=True)
    fig["isr_worst_cycles"] = s["isr_profiled_max_cycles"]
    fig["isr_worst_us"] = round(s["isr_profiled_max_cycles"] / 16, 2)
    fig["isr_mean_cycles"] = s["isr_profiled_mean_cycles"]
    fig["isr_profile_record_exact"] = ok
    fig["stack_free_bytes_after_demo"] = s.get("stack_free_bytes")

    # step edges against the ideal trajectory, all four axes at once, and the step
    # interrupt's load (compare A, nested compare B included) at each rate
    sweep = []
    top = _advertised_rate()
    fig["advertised_max_step_rate"] = top
    # rates over the advertised one are refused by the host (no edge logged)
    rates = (
        [top]
        if args.quick
        else sorted({r for r in (2_500, 5_000, 7_500, 10_000) if r < top} | {top})
    )
    for rate in rates:
        log = Path(tempfile.mkdtemp()) / "steps.txt"
        batch = _rate_batch(rate, n=200)
        s, _, ok, _ = _stream("avr", batch, profile=True, step_log=log)
        err = _step_error(log, batch)
        motion_cycles = batch.ticks.sum() * 160
        # compare A (compare B nested in it included) and compare B on its own
        isr_cycles = s["isr_profiled_mean_cycles"] * s["isr_profiled_count"]
        isr_cycles += s.get("compare_b_outside_cycles", 0)
        load = isr_cycles / max(s["cycles"], 1)
        sweep.append(
            {
                "steps_per_s_each_axis": rate,
                "step_err_vs_ideal_worst_us": err["worst_us"],
                "step_err_vs_ideal_p99_us": err["p99_us"],
                "isr_load_pct_whole_run": round(100 * load, 1),
                "isr_load_pct_of_motion": round(100 * isr_cycles / motion_cycles, 1),
                "min_pulse_high_us": s["min_pulse_high_us"],
                "min_dir_setup_us": s["min_dir_setup_us"],
                "lost_steps": s["lost_steps"],
                "late_pulses": s["late_pulses"],
                "record_exact": ok,
            }
        )
    fig["step_timing"] = sweep

    # a print's mix: one module at a share of the advertised rate, the others at 3/4 and
    # 1/2 of it, the extruder at 1/10: the steps fall apart, each its own compare B
    mix = []
    for share in (0.6, 0.8, 1.0) if not args.quick else (1.0,):
        rates_mix = [int(top * share * f) for f in (1.0, 0.75, 0.5, 0.1)]
        log = Path(tempfile.mkdtemp()) / "steps.txt"
        batch = _rate_batch(rates_mix, n=200)
        s, _, ok, _ = _stream("avr", batch, profile=True, step_log=log)
        err = _step_error(log, batch)
        isr_cycles = s["isr_profiled_mean_cycles"] * s["isr_profiled_count"]
        isr_cycles += s.get("compare_b_outside_cycles", 0)
        mix.append(
            {
                "steps_per_s_per_axis": rates_mix,
                "step_err_vs_ideal_worst_us": err["worst_us"],
                "step_err_vs_ideal_p99_us": err["p99_us"],
                "isr_load_pct_of_motion": round(100 * isr_cycles / (batch.ticks.sum() * 160), 1),
                "overruns": s["overruns"],
                "late_pulses": s["late_pulses"],
                "harness_clock_slips": s.get("motion_clock_slips"),
                "record_exact": ok,
            }
        )
    fig["step_timing_print_mix"] = mix

    # streaming at 1x over 250000 baud: segments of ever shorter duration (3-4 s of
    # device time each), clean and with 1e-3 corruption and drop per byte
    n_s = 2.0 if args.quick else 4.0
    stream = []
    # down to the device's shortest segment (CAPS: 40 units, one 0.4 ms step tick)
    for ticks in (200, 130, 100, 80, 65, 50, 45, 40):
        batch = _short_batch(ticks, int(n_s * CLOCK_HZ / ticks))
        payload, _ = encode_segments(batch, SegmentContext())
        row: dict[str, Any] = {"segment_ms": ticks / 100, "segments_per_s": CLOCK_HZ // ticks}
        row["payload_bytes_per_segment"] = round(len(payload) / len(batch), 2)
        for name, faults in (("clean", None), ("faults", "corrupt=0.001,drop=0.001")):
            s, _, ok, _ = _stream("avr", batch, faults=faults)
            row[f"{name}_record_exact"] = ok
            row[f"{name}_host_retransmits"] = s["host_retransmits"]
            row[f"{name}_main_loop_max_us"] = s.get("main_loop_max_us")
        stream.append(row)
    fig["streaming"] = stream
    for name in ("clean", "faults"):
        exact = [r[f"{name}_record_exact"] for r in stream]
        fig[f"segments_per_s_streamed_{name}"] = max(
            (r["segments_per_s"] for r, ok in zip(stream, exact) if ok), default=0
        )
        # every row up to this rate exact (the batches differ: 0.5 ms segments mostly
        # repeat the one before, 0.65 ms ones do not)
        upto = next((i for i, ok in enumerate(exact) if not ok), len(stream))
        fig[f"segments_per_s_all_exact_up_to_{name}"] = (
            stream[upto - 1]["segments_per_s"] if upto else 0
        )
    # the measure: 30 s of device time, 2000/s clean and 1000/s with faults
    if not args.quick:
        sustained = {}
        for name, ticks, faults in (
            ("clean_2000_per_s", 50, None),
            ("faults_1000_per_s", 100, "corrupt=0.001,drop=0.001"),
        ):
            s, _, ok, _ = _stream("avr", _short_batch(ticks, 30 * CLOCK_HZ // ticks), faults=faults)
            sustained[name] = {
                "record_exact": ok,
                "device_s": s.get("sim_seconds"),
                "host_retransmits": s["host_retransmits"],
                "host_timeouts": s["host_timeouts"],
                # real time: the most simavr fell behind the wall clock (it then runs
                # flat out to catch up, faster than a board would)
                "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
            }
        fig["streaming_30_s"] = sustained
    # the same with print-like segments (varied deltas), at the rate the host plans for
    rate, min_ticks = _announced()
    fig["streaming_print_like"] = _print_like_streams(
        args.stream_rate or int(0.9 * rate),
        rate,
        seconds=5.0 if args.quick else 30.0,
        ladder=not args.quick,
    )
    seg = stream[0]["payload_bytes_per_segment"]
    per_seg = seg * (1 + OVERHEAD / 120)  # frames of the 120-byte max_payload the AVR asks for
    fig["segments_per_s_line_limit_250000_baud"] = round(BAUD / 10 / per_seg)

    fig["heaters_off_after_watchdog_s"] = {
        state: _heaters_off_latency(state)
        for state in ("idle, heating", "moving", "faulted (underrun)", "waiting (WAIT_HEATER)")
    }
    fig["heaters_autotune_210_c"] = _heaters()
    fig["rate_search"] = _rate_search()
    fig["cup_on_announced_limits"] = _cup(rate, min_ticks)
    print(json.dumps(fig, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
