"""The measurements bench/firmware.py reports, one function each: a stream through the
simavr harness, the step edges against their ideal times, the firmware's size and stack,
the heaters, the highest step rate per configuration, the print-like streams, the cup.

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
"""

from __future__ import annotations

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
from firmware_rates import CLOCK_HZ
from step_schedule import print_like

from cdprhost.link import LinkError, open_link
from cdprhost.sim import avr_device
from firmware_protocol.messages import Configure, Flush, Message, Segment, SetHeater, WaitHeater
from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_TO_REST
from firmware_protocol.segments import (
    SegmentBatch,
    SegmentContext,
    encode_segments,
    peak_step_rates,
)
from firmware_protocol.streams import expected_record

#: the device states the host falls silent in (heaters_off_latency), each with what puts
#: the device in it after a heater is set
HEATER_STATES: dict[str, tuple[Message, ...]] = {
    "idle, heating": (),
    "moving": (Segment(ticks=1_000_000, deltas=(2000, 0, 0, 0), ramp=RAMP_TO_REST), Flush()),
    "faulted (underrun)": (Segment(ticks=2000, deltas=(40, 0, 0, 0), ramp=RAMP_CONSTANT), Flush()),
    "waiting (WAIT_HEATER)": (WaitHeater(0, 1),),
}
#: the faults of the lossy streams: 1e-3 corruption and drop per byte
FAULTS = "corrupt=0.001,drop=0.001"
#: the issue's 30 s streams: (name, ticks a segment, faults): 2000/s clean, 1000/s with
#: 1e-3 corruption and drop
ISSUE_STREAMS: tuple[tuple[str, int, str | None], ...] = (
    ("clean_2000_per_s", 50, None),
    ("faults_1000_per_s", 100, FAULTS),
)


def stream(
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


def step_error(log: Path, batch: SegmentBatch) -> dict[str, float]:
    """Every rising step edge the harness logged against its ideal time: worst and 99th
    percentile of |error| in us (1 clock unit = 10 us, 16 cycles = 1 us)."""
    err, _ = rates_bench.edge_errors(rates_bench.step_log_edges(log), batch)
    return rates_bench.edge_figures(err)


def advertised_rate() -> int:
    """The firmware's MAX_STEP_RATE (steps/s on any one axis, IDENT max_step_rate)."""
    text = (avr_device.FIRMWARE_DIR / "src" / "config.h").read_text()
    m = re.search(r"#define MAX_STEP_RATE (\d+)UL", text)
    assert m, "MAX_STEP_RATE not found in firmware/src/config.h"
    return int(m.group(1))


def short_batch(ticks: int, n: int) -> SegmentBatch:
    """``n`` segments of ``ticks`` each, three modules and the extruder at a few kHz."""
    rng = np.random.default_rng(5)
    rate = rng.integers(1000, 4000, size=(n, 4))
    sign = np.where((np.arange(n) // 50) % 2 == 0, 1, -1)[:, None]
    deltas = sign * np.maximum(1, rate * ticks // CLOCK_HZ)
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


def size() -> dict[str, Any]:
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


def heaters_off_latency(state: str, watchdog_ms: int = 500) -> float:
    """Seconds from the host's last byte to the heater pin going low, minus the watchdog
    time, with the device in ``state`` when the host falls silent (wall time: the link's
    clock in the harness)."""
    from tests.conformance.device import RawHost, start

    dev = start("avr", Path(tempfile.mkdtemp()), "--speedup", "1")
    h = RawHost(dev.path)
    try:
        h.hello()
        configure = Configure(watchdog_ms=watchdog_ms, start_ticks=100_000, flow_ticks=12_500)
        h.send(configure, SetHeater(0, 1500))
        if HEATER_STATES[state]:
            h.send(*HEATER_STATES[state])
        h.pump(0.5)
        h.keepalive = 0  # the host dies: nothing more is sent
        end = time.monotonic() + 3 * watchdog_ms / 1000
        while time.monotonic() < end:
            h.pump(0.05)
    finally:
        h.close()
        dev.stop()
    return round(dev.stats()["heater_on_silence_max_s"] - watchdog_ms / 1000, 4)


def heaters_off_latencies() -> dict[str, float]:
    """heaters_off_latency in each of HEATER_STATES."""
    return {state: heaters_off_latency(state) for state in HEATER_STATES}


def autotune(kind: str) -> dict[str, Any]:
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


def heaters() -> dict[str, Any]:
    out = {kind: autotune(kind) for kind in ("python", "avr")}
    py, avr = out["python"], out["avr"]
    if "kp" in py and "kp" in avr:
        out["avr_vs_python_pct"] = {
            k: round(100 * (avr[k] - py[k]) / py[k], 1) for k in ("kp", "ki", "kd", "period_s")
        }
    return out


def announced() -> tuple[int, int]:
    """What the default build announces: IDENT max_step_rate and CAPS min_segment_ticks."""
    with rates_bench.harness(rates_bench.default_build(), profile=False) as (link, _):
        assert link.identity is not None
        caps = link.caps
        return link.identity.max_step_rate, caps.min_segment_ticks if caps else 1


def rate_search(
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


def print_like_batch(rate: int, ticks: int, seconds: float, limit: int) -> SegmentBatch:
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


def within_rate(batch: SegmentBatch, rate: int) -> SegmentBatch:
    """``batch`` with each segment slowed, where needed, to 90 % of ``rate`` on its busiest
    axis (the same steps: the host refuses a stream over the device's announced rate; the
    demo's last segment, braking to rest from twice its mean speed, is the one over)."""
    peak = peak_step_rates(batch, CLOCK_HZ).max(axis=1)
    stretch = np.maximum(1.0, peak / (0.9 * rate))
    ticks = np.ceil(batch.ticks * stretch).astype(np.int64)
    return SegmentBatch(ticks, batch.deltas, batch.ramps)


def print_like_streams(
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
            s, _, ok, _ = stream("avr", print_like_batch(rate, ticks, 3.0, limit))
            steps.append(
                {
                    "segments_per_s": CLOCK_HZ // ticks,
                    "record_exact": ok,
                    "device_s": s.get("sim_seconds"),
                    "sim_behind_wall_max_ms": s.get("behind_wall_max_ms"),
                }
            )
        out["ladder_clean_3_s"] = steps
    for name, ticks, faults in ISSUE_STREAMS:
        batch = print_like_batch(rate, ticks, seconds, limit)
        s, _, ok, _ = stream("avr", batch, faults=faults)
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


def cup(rate: int, min_ticks: int) -> dict[str, Any]:
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


def stack_free() -> int | None:
    """The static worst-case stack's free bytes (firmware/tools/stack_usage.py)."""
    tool = avr_device.FIRMWARE_DIR / "tools" / "stack_usage.py"
    out = subprocess.run(
        [sys.executable, str(tool)], capture_output=True, text=True, check=False
    ).stdout
    m = re.search(r"(-?\d+) B free", out)
    return int(m.group(1)) if m else None
