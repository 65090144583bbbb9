"""The AVR firmware's highest step rate per configuration, in simulated time (issue 29).

Used by bench/firmware.py (`--rates`, `--acceptance`). A configuration is a rate per axis
as shares of R: one module alone, three modules in step, three modules out of step with
the extruder running, a print's mix. Each point streams constant-speed segments of
10 ms (back and forth, the last braking to rest) to a firmware build announcing at
least R (``MAX_STEP_RATE`` raised by a build override into ``firmware/build/rate-N``,
so the default build the tests use is not touched), and judges it on the harness's
figures (firmware/sim/harness.c): every rising step edge against its ideal time on the
segment's profile (PROTOCOL.md 5.1), worst within 10 us and p99 within 5 us, as many
edges as the segments ask, no tick overrun, no lost or late step (HEALTH), no clock
slip, the record exact. The search bisects R between a rate that passes and one that
fails, to ``RESOLUTION`` steps/s.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cdprhost.link import HostLink, LinkError, open_link, wire_cuts
from cdprhost.sim import avr_device
from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_FROM_REST, RAMP_TO_REST, step_times
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.streams import expected_record

CLOCK_HZ = 100_000
CYCLES_PER_UNIT = 160  # 16 MHz / 100 kHz: the step log is in cycles of the motion clock
WORST_US, P99_US = 10.0, 5.0  # the edge limits
RESOLUTION = 500  # steps/s: where the search stops
SEGMENT_TICKS = 1000  # 10 ms constant-speed segments
SEGMENTS = 30  # 300 ms of device time a point

#: rate of each axis (three modules, extruder) as a share of R; the out-of-step modules
#: differ by a step or two a segment, so their edges drift across each other
CONFIGS: dict[str, tuple[float, float, float, float]] = {
    "one module alone": (1.0, 0.0, 0.0, 0.0),
    "three modules in step": (1.0, 1.0, 1.0, 0.0),
    "three modules out of step, extruder running": (1.0, 0.997, 0.993, 0.1),
    "a print's mix": (1.0, 0.75, 0.5, 0.1),
}
#: where each search starts looking (steps/s): the top a point may reach
CEILINGS = {
    "one module alone": 200_000,
    "three modules in step": 80_000,
    "three modules out of step, extruder running": 80_000,
    "a print's mix": 80_000,
}


#: the build options of the step engine (firmware/src/step_engine.c, docs/step-engine.md)
ENGINE_CFLAGS = "-DSTEP_ENGINE=1"


@dataclass(frozen=True)
class Build:
    """A firmware build for the simulator: the ELF and the harness that runs it."""

    max_step_rate: int | None  # None: the default build (config.h's rate)
    elf: Path
    harness: Path
    cflags: str = ""  # build options beside MAX_STEP_RATE ("": the default engine)

    @property
    def engine(self) -> str:
        """Which step engine the build steps with, for the tables."""
        if not self.cflags:
            return "default (tick DDA)"
        return "step engine" if self.cflags == ENGINE_CFLAGS else f"with {self.cflags}"


def variant(max_step_rate: int, cflags: str = "") -> Build:
    """The simulator build announcing ``max_step_rate`` (rounded up to a multiple of 200,
    as motion.c's rate check needs) with the build options ``cflags`` (``ENGINE_CFLAGS``:
    the step engine), in its own build directory: ``build/rate-N`` for the default engine,
    ``build/engine-rate-N`` for the step engine, ``build/custom-rate-N`` (rebuilt each time)
    for other options."""
    rate = -(-max_step_rate // 200) * 200
    cflags = " ".join(cflags.split())
    kind = {"": "", ENGINE_CFLAGS: "engine-"}.get(cflags, "custom-")
    build = f"build/{kind}rate-{rate}"
    flags = f"{cflags} -DMAX_STEP_RATE={rate}UL".strip()
    # a custom directory's options change from run to run, its files do not: -B
    rebuild = ["-B"] if kind == "custom-" else []
    proc = subprocess.run(
        ["make", "-s", *rebuild, "-C", str(avr_device.FIRMWARE_DIR), f"BUILD={build}"]
        + [f"EXTRA_CFLAGS={flags}", "sim"],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode:
        raise SystemExit(f"building the firmware with {flags} failed:\n{proc.stderr}")
    out = avr_device.FIRMWARE_DIR / build
    return Build(rate, out / "cdpr-sim.elf", out / "cdpr-sim", cflags)


def default_build() -> Build:
    return Build(None, avr_device.ELF, avr_device.HARNESS)


#: the out-of-step modules at least a step a segment apart (steps/s), whatever R
APART = CLOCK_HZ // SEGMENT_TICKS


def rates_of(config: str, rate: float) -> list[int]:
    """Steps/s of each axis for ``config`` at R = ``rate``."""
    out = [round(rate * share) for share in CONFIGS[config]]
    if "out of step" in config:
        out[1] = min(out[1], out[0] - APART)
        out[2] = min(out[2], out[1] - APART)
    return out


def constant_batch(
    rates: list[int], n: int = SEGMENTS, ticks: int = SEGMENT_TICKS, *, brake: bool = True
) -> SegmentBatch:
    """``n`` constant-speed segments at ``rates`` (steps/s per axis), reversing every fourth
    segment, the last braking to rest from the same rate (half the distance); without
    ``brake``, the last at the rates too and a segment at rest after it (a stop: only
    steady segments, which the step engine steps; it leaves ramps to the tick's DDA)."""
    d = np.array(rates, dtype=np.int64) * ticks // CLOCK_HZ
    sign = np.where((np.arange(n) // 4) % 2 == 0, 1, -1)
    deltas = np.outer(sign, d)
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    if not brake:
        deltas = np.vstack([deltas, np.zeros((1, len(d)), dtype=np.int64)])
        return SegmentBatch(np.full(n + 1, ticks), deltas, np.append(ramps, RAMP_CONSTANT))
    deltas[-1] //= 2
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


def ramp_batch(
    rates: list[int], cycles: int = 5, steady: int = 3, ticks: int = SEGMENT_TICKS
) -> SegmentBatch:
    """From rest up to ``rates`` in one segment (its end speed twice its mean), ``steady``
    segments at the rates, back to rest in one; ``cycles`` times, reversing each time."""
    d = np.array(rates, dtype=np.int64) * ticks // CLOCK_HZ
    one = [RAMP_FROM_REST] + [RAMP_CONSTANT] * steady + [RAMP_TO_REST]
    codes = np.array(one * cycles, dtype=np.int16)
    share = np.where(codes == RAMP_CONSTANT, 2, 1)  # halves: the ramps cover half the way
    sign = np.repeat(np.where(np.arange(cycles) % 2 == 0, 1, -1), len(one))
    deltas = (sign * share)[:, None] * (d[None, :] // 2)
    return SegmentBatch(np.full(len(codes), ticks), deltas, codes)


#: the device's longest payload (IDENT max_payload), a segment without its block at most
#: SEGMENT_MAX_BYTES of it (PROTOCOL.md 5.2)
MAX_PAYLOAD = 120
#: frames acknowledged before a point's stream (the link's frames start short and grow by 2
#: bytes with each clean one: at MAX_PAYLOAD after about 45)
WARM_FRAMES = 48


def cut_for_blocks(batch: SegmentBatch, payload: int = MAX_PAYLOAD) -> SegmentBatch:
    """``batch`` with its ramps cut until their blocks fit a payload, as the host cuts a
    batch it did not plan (cdprhost.link.wire_cuts): every axis of a ramp then steps from
    its block (the step engine's), none on the device's own stepping."""
    return wire_cuts.cut_for_blocks(batch, payload)


def warm_link(link: HostLink, frames: int = WARM_FRAMES) -> None:
    """Frames acknowledged clean before the stream, so its frames are full length (the
    link starts them short and grows them on a clean line) and a ramp's block goes with
    it, as in a print some seconds in."""
    for _ in range(frames):
        link.request_status()


def ideal_edges_us(batch: SegmentBatch, axis: int) -> np.ndarray:
    """The exact time (us of motion) of every step of ``axis`` on its segments' profiles."""
    starts = np.concatenate([[0], np.cumsum(batch.ticks)[:-1]])
    parts = [
        starts[i] + step_times(int(batch.deltas[i, axis]), int(batch.ticks[i]), int(batch.ramps[i]))
        for i in range(len(batch))
    ]
    return np.concatenate(parts) * 1e6 / CLOCK_HZ if parts else np.zeros(0)


def edge_errors(edges: np.ndarray, batch: SegmentBatch) -> tuple[np.ndarray, int]:
    """|error| (us) of every logged rising edge (rows ``axis cycles``) against its ideal
    time, and the edges missing or extra against the steps the segments ask for."""
    errs, miscount = [], 0
    for axis in range(4):
        got = edges[edges[:, 0] == axis, 1] / (CYCLES_PER_UNIT / 10) if len(edges) else np.zeros(0)
        want = ideal_edges_us(batch, axis)
        miscount += abs(len(got) - len(want))
        m = min(len(got), len(want))
        errs.append(np.abs(got[:m] - want[:m]))
    e = np.concatenate(errs)
    return (e if len(e) else np.zeros(1)), miscount


def step_log_edges(log: Path) -> np.ndarray:
    """The harness's step log (CDPR_SIM_STEP_LOG) as rows ``axis cycles``, one a rising
    edge (none when the log is empty)."""
    return np.loadtxt(log, dtype=np.int64, ndmin=2) if log.stat().st_size else np.zeros((0, 2))


def edge_figures(err: np.ndarray) -> dict[str, float]:
    """The worst and 99th-percentile edge error (us, rounded to 0.01) of ``err``."""
    return {
        "worst_us": round(float(err.max()), 2),
        "p99_us": round(float(np.percentile(err, 99)), 2),
    }


@contextmanager
def harness(
    build: Build, *, speedup: float = 4.0, profile: bool = True, folder: Path | None = None
) -> Iterator[tuple[HostLink, Path]]:
    """The harness running ``build`` and a link to it; the folder of its record
    (record.jsonl), step log (steps.txt) and figures (stats.json), written as the harness
    exits: ``folder`` (the caller's, kept), or a temporary one removed with the block
    (each run's step log is about 200 kB: a temporary folder left behind by every run
    filled /tmp)."""
    with contextlib.ExitStack() as stack:
        if folder is None:
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        with _running(build, speedup, profile, folder) as link:
            yield link, folder


@contextmanager
def _running(build: Build, speedup: float, profile: bool, tmp: Path) -> Iterator[HostLink]:
    env = dict(os.environ, CDPR_SIM_STEP_LOG=str(tmp / "steps.txt"))
    if profile:
        env["CDPR_SIM_PROFILE_ISR"] = "1"
    cmd = [str(build.harness), str(build.elf), "--speedup", f"{speedup:g}"]
    cmd += ["--record", str(tmp / "record.jsonl"), "--stats", str(tmp / "stats.json")]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    assert proc.stdout is not None
    try:
        link = open_link(proc.stdout.readline().strip())
        try:
            yield link
        finally:
            link.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)


def _stats(tmp: Path) -> dict[str, Any]:
    stats = tmp / "stats.json"
    s: dict[str, Any] = json.loads(stats.read_text()) if stats.exists() else {}
    # the step interrupts' cycles as the harness profiles them (CDPR_SIM_PROFILE_ISR):
    # every step vector of either engine (Timer1 compare A/B, Timer3 compare A-C, Timer5
    # compare A), from its vector to its RETI, nested ones counted once
    s["isr_cycles"] = s.get("step_isr_cycles", 0)
    return s


def axis_edge_counts(edges: np.ndarray, batch: SegmentBatch) -> list[str]:
    """Per axis, ``logged/asked`` rising edges (rows ``axis cycles``)."""
    got = [int((edges[:, 0] == axis).sum()) if len(edges) else 0 for axis in range(4)]
    return [f"{g}/{len(ideal_edges_us(batch, axis))}" for axis, g in enumerate(got)]


def run_batch(
    build: Build,
    batch: SegmentBatch,
    *,
    speedup: float = 4.0,
    profile: bool = True,
    blocks: bool | None = None,
) -> dict[str, Any]:
    """Stream ``batch`` to the harness running ``build`` and judge it: the figures of one
    point (``passed`` against the issue's limits). ``blocks`` (by default for the step
    engine): the ramps cut until their blocks fit (cut_for_blocks) and the link's frames
    grown first (warm_link), so every ramp axis steps from its block."""
    if blocks is None:
        blocks = bool(build.cflags)
    if blocks:
        batch = cut_for_blocks(batch)
    with tempfile.TemporaryDirectory() as folder:
        return _judged(build, batch, speedup, profile, blocks, Path(folder))


def _judged(
    build: Build,
    batch: SegmentBatch,
    speedup: float,
    profile: bool,
    blocks: bool,
    tmp: Path,
) -> dict[str, Any]:
    """run_batch's run, its harness's files in ``tmp``."""
    refused = ""
    with harness(build, speedup=speedup, profile=profile, folder=tmp) as (link, _):
        try:
            if blocks:
                warm_link(link)
            link.queue_segments(batch)
            link.wait_idle(300)
        except LinkError as e:  # an underrun, a refused segment: this rate failed
            refused = str(e)[:200]
    record, log = tmp / "record.jsonl", tmp / "steps.txt"
    rows = [json.loads(x) for x in record.read_text().splitlines() if x.strip()]
    s = _stats(tmp)
    edges = step_log_edges(log)
    err, miscount = edge_errors(edges, batch)
    out = {
        "steps_per_s": [int(x) for x in np.abs(batch.deltas[0]) * CLOCK_HZ // batch.ticks[0]],
        **edge_figures(err),
        "edges_missing_or_extra": miscount,
        "edges": axis_edge_counts(edges, batch),
        "overruns": s.get("overruns", -1),
        "lost_steps": s.get("lost_steps", -1),
        "late_pulses": s.get("late_pulses", -1),
        "clock_slips": s.get("motion_clock_slips", -1),
        "record_exact": not refused and rows == expected_record(batch),
        "isr_cycles": s["isr_cycles"],
        # Timer1's tick interrupts over the whole run (idle ticks included: 400 us each)
        "tick_interrupts": s.get("isr_profiled_count", -1),
        "run_cycles": s.get("cycles", 0),
        "motion_cycles": int(batch.ticks.sum()) * CYCLES_PER_UNIT,
    }
    if refused:
        out["refused"] = refused
    out["passed"] = passes(out)
    return out


def passes(point: dict[str, Any]) -> bool:
    """The issue's limits: every edge within 10 us, p99 within 5 us, all edges there, no
    overrun, lost or late step, no clock slip, the record exact."""
    return bool(
        point["record_exact"]
        and point["worst_us"] <= WORST_US
        and point["p99_us"] <= P99_US
        and point["edges_missing_or_extra"] == 0
        and point["overruns"] == 0
        and point["lost_steps"] == 0
        and point["late_pulses"] == 0
        and point["clock_slips"] == 0
    )


def isr_load_pct(point: dict[str, Any], idle_share: float) -> float:
    """The step interrupts' share of the motion's cycles (%), the idle ticks outside
    motion (at ``idle_share`` of their cycles) taken out."""
    idle = max(point["run_cycles"] - point["motion_cycles"], 0) * idle_share
    return round(100 * max(point["isr_cycles"] - idle, 0) / point["motion_cycles"], 1)


def idle_isr_share(build: Build, seconds: float = 0.5) -> float:
    """The step interrupts' share of the CPU with nothing moving (a session open,
    ``seconds`` of wall time)."""
    with tempfile.TemporaryDirectory() as folder:
        with harness(build, folder=Path(folder)) as (_link, tmp):
            time.sleep(seconds)
        s = _stats(tmp)
    return float(s["isr_cycles"]) / max(int(s.get("cycles", 0)), 1)


def highest_rate(
    build: Build,
    config: str,
    *,
    lo: int = 1_000,
    hi: int | None = None,
    repeats: int = 3,
    speedup: float = 4.0,
    brake: bool = True,
) -> dict[str, Any]:
    """The highest R (a multiple of RESOLUTION) at which ``config`` passes: bisected
    between ``lo`` and ``hi`` on one run a point, then confirmed on ``repeats`` runs
    (stepping down while one of them fails: a host byte arriving with a step makes a
    run differ from the next). Its figures are the worst of its runs; ``fail`` is the
    lowest rate seen failing and why. ``brake``: constant_batch's last segment."""
    hi = hi or CEILINGS[config]
    runs: dict[int, list[dict[str, Any]]] = {}

    def run(r: int) -> dict[str, Any]:
        batch = constant_batch(rates_of(config, r), brake=brake)
        p = run_batch(build, batch, speedup=speedup)
        runs.setdefault(r, []).append(p)
        return p

    def passed(r: int) -> bool:
        return all(p["passed"] for p in runs.get(r) or [run(r)])

    top = hi
    if passed(hi):
        lo = hi
    elif passed(lo):
        while hi - lo > RESOLUTION:
            mid = max((lo + hi) // 2 // RESOLUTION * RESOLUTION, lo + RESOLUTION)
            lo, hi = (mid, hi) if passed(mid) else (lo, mid)
        while lo > RESOLUTION:
            while passed(lo) and len(runs[lo]) < repeats:
                run(lo)
            if passed(lo):
                break
            lo -= RESOLUTION
    at = runs.get(lo, [])
    failed = sorted(r for r, ps in runs.items() if not all(p["passed"] for p in ps))
    out: dict[str, Any] = {"config": config, "rate": lo if at and passed(lo) else None}
    if at:
        out["worst_us"] = max(p["worst_us"] for p in at)
        out["p99_us"] = max(p["p99_us"] for p in at)
        out["runs_at_rate"] = len(at)
        out["at"] = at[0]
    if failed:
        f = failed[0]
        out["lowest_fail"] = f
        out["fail_reason"] = fail_reason(next(p for p in runs[f] if not p["passed"]))
    out["points_run"] = sum(len(ps) for ps in runs.values())
    out["ceiling"] = top
    return out


def fail_reason(point: dict[str, Any]) -> str:
    """The first limit a failed point broke, in a few words."""
    if point.get("refused"):
        return "refused: " + point["refused"][:80]
    for key in ("overruns", "lost_steps", "late_pulses", "clock_slips", "edges_missing_or_extra"):
        if point[key]:
            return f"{key} {point[key]}"
    if point["worst_us"] > WORST_US:
        return f"worst edge {point['worst_us']} us"
    if point["p99_us"] > P99_US:
        return f"p99 {point['p99_us']} us"
    if not point["record_exact"]:
        return "record not exact"
    return ""
