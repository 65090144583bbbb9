"""Step schedules (firmware_protocol/step_schedule.py) on real and print-like streams.

    python bench/step_schedule.py [--tol-us 1.0] [--cup FILE.npz] [--seconds 2]
        [--cup-segments 2000] [--repeats 3]

For the design note docs/step-engine.md: per axis and segment, the chunks a schedule
needs for every edge within ``--tol-us`` of its profile, the worst edge error, and the
bytes a segment would cost on the wire beyond today's segment (the schedule blocks of
the axes the device cannot predict, coded against its guess), against sending each
chunk whole
(``interval, count, add`` in whole cycles, as a Klipper-style ``queue_step`` does). The
blocks are coded by firmware_protocol/schedule_block.py.

Streams:
- ``print_like``: 0.5 ms segments (2000/s), the busiest module at 33,000 steps/s, the
  others at 3/4 and 1/2 of it, the extruder at 1/10, every joint speed varying along a
  curve (the deltas differ segment to segment), with a ramp from and to rest;
- ``cup``: the wire segments of ``examples/example.gcode`` on ``paper-prototype`` at the
  profile's own limits, if ``--cup`` names an npz of them (``ticks``, ``deltas``,
  ``ramps``; the capture is in the note).

``fitter`` (each stream; the cup's first ``--cup-segments``): the host's planning time,
CPU seconds (``time.process_time``, the best of ``--repeats``: the machine may be shared),
of ``plan_schedules`` over the whole batch and of each ramp segment planned alone, per ramp
segment (a segment with a ramp code: its moving axes are fitted), against the first fitter
(``tests/protocol/step_schedule_reference.py``: the first ``plan_schedules``, one count
tried at a time) on the same segments in the same run: ``old_over_new`` is the speed-up;
the chunks both found are counted, and the schedules that are the same.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_protocol.ramp_profile import RAMP_FROM_REST, RAMP_TO_REST
from firmware_protocol.schedule_block import encode_block
from firmware_protocol.schedule_fit import fit_axis, plan_schedules
from firmware_protocol.segments import SegmentBatch, SegmentContext, encode_segments
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    AxisSchedule,
    cycles_per_tick,
    ideal_edges,
    predicted_error,
    reciprocal_table,
    schedule_error,
)
from firmware_protocol.varint import encode_uvarint, zigzag
from tests.protocol.step_schedule_reference import reference_plan_schedules

CLOCK_HZ = 100_000


def _vlen(value: int) -> int:
    return len(encode_uvarint(zigzag(value)))


def print_like(seconds: float, rate: float = 33_000.0, ticks: int = 50) -> SegmentBatch:
    n = int(seconds * CLOCK_HZ / ticks)
    t = (np.arange(n + 1) * ticks) / CLOCK_HZ
    share = np.array([1.0, 0.75, 0.5, 0.1])
    phase = np.array([0.0, 2.1, 4.2, 1.0])
    # speeds vary along a curve (period 0.2 s) between 60 % and 100 % of each axis's rate
    pos = np.stack(
        [
            rate * s * (0.8 * t - 0.2 * 0.2 / (2 * np.pi) * np.cos(2 * np.pi * t / 0.2 + p))
            for s, p in zip(share, phase)
        ],
        axis=1,
    )
    deltas = np.diff(np.floor(pos).astype(np.int64), axis=0)
    ramps = np.full(n, -1, dtype=np.int16)
    ramps[0] = RAMP_FROM_REST
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


def _whole_chunks(batch: SegmentBatch, tol: float, limit: int) -> tuple[float, int]:
    """Option A: every moving axis's chunks sent whole (message and stepper, interval in
    whole cycles, count, add), over the first ``limit`` segments; bytes per segment."""
    cpt = cycles_per_tick(CLOCK_HZ)
    total = 0
    m = min(limit, len(batch))
    for i in range(m):
        for k in range(4):
            n = int(batch.deltas[i, k])
            if n:
                ideal = ideal_edges(n, int(batch.ticks[i]), int(batch.ramps[i]), cpt)
                for c in fit_axis(ideal, tol).chunks:
                    whole = c.interval >> FRAC_BITS
                    total += 2 + _vlen(whole) + _vlen(c.count) + _vlen(c.add >> FRAC_BITS)
    return total / m, m


def analyse(batch: SegmentBatch, tol_us: float, whole_limit: int) -> dict[str, float]:
    cpt = cycles_per_tick(CLOCK_HZ)
    tol = tol_us * 16.0
    table = reciprocal_table(cpt)
    t0 = time.perf_counter()
    explicit = plan_schedules(batch, cpt, tol, table)
    spent = time.perf_counter() - t0
    n = batch.deltas
    moving = n != 0
    ticks = np.broadcast_to(batch.ticks[:, None], n.shape)
    predicted_axes = moving.copy()
    for i, k in explicit:
        predicted_axes[i, k] = False
    errors = [predicted_error(n[predicted_axes], ticks[predicted_axes], table, cpt)]
    chunks = int(predicted_axes.sum())
    by_segment: dict[int, dict[int, AxisSchedule]] = {}
    for (i, k), sched in explicit.items():
        ideal = ideal_edges(int(n[i, k]), int(batch.ticks[i]), int(batch.ramps[i]), cpt)
        errors.append(np.abs(schedule_error(sched, ideal)))
        chunks += len(sched.chunks)
        by_segment.setdefault(i, {})[k] = sched
    extra = sum(
        len(encode_block(n[i].tolist(), int(batch.ticks[i]), scheds, table))
        for i, scheds in by_segment.items()
    )
    err = np.concatenate(errors) / 16.0
    data, _ = encode_segments(batch, SegmentContext())
    seconds = float(batch.ticks.sum()) / CLOCK_HZ
    whole, whole_n = _whole_chunks(batch, tol, whole_limit)
    return {
        "segments": len(batch),
        "device_s": round(seconds, 2),
        "segments_per_s": round(len(batch) / seconds, 1),
        "steps": int(np.abs(n).sum()),
        "chunks_per_axis_segment": round(chunks / max(int(moving.sum()), 1), 3),
        "edge_error_us_max": round(float(err.max()), 3),
        "edge_error_us_p99_of_axis_worst": round(float(np.percentile(err, 99)), 3),
        "segment_bytes_today": round(len(data) / len(batch), 2),
        "schedule_bytes_per_segment": round(extra / len(batch), 2),
        "segments_with_schedule_block": round(len(by_segment) / len(batch), 4),
        "whole_chunk_bytes_per_segment": round(whole, 2),
        "whole_chunk_segments_measured": whole_n,
        "host_plan_us_per_segment": round(1e6 * spent / len(batch), 1),
    }


def _best(run, repeats: int) -> float:
    spent = []
    for _ in range(repeats):
        t0 = time.process_time()
        run()
        spent.append(time.process_time() - t0)
    return min(spent)


def fitter_time(batch: SegmentBatch, tol_us: float, repeats: int) -> dict[str, float]:
    """The fitter's time per ramp segment, planned as one batch and one segment at a time,
    against the first fitter on the same axes (its time is the baseline)."""
    cpt = cycles_per_tick(CLOCK_HZ)
    tol = tol_us * 16.0
    table = reciprocal_table(cpt)
    ramps = np.flatnonzero(batch.ramps >= 0)
    alone = [batch[i : i + 1] for i in ramps]
    new = plan_schedules(batch, cpt, tol, table)
    keys = sorted(new)
    old = reference_plan_schedules(batch, cpt, tol, table)
    t_new = _best(lambda: plan_schedules(batch, cpt, tol, table), repeats)
    t_old = _best(lambda: reference_plan_schedules(batch, cpt, tol, table), repeats)
    a_new = _best(lambda: [plan_schedules(b, cpt, tol, table) for b in alone], repeats)
    a_old = _best(lambda: [reference_plan_schedules(b, cpt, tol, table) for b in alone], repeats)
    per = 1e3 / max(len(ramps), 1)
    return {
        "segments": len(batch),
        "ramp_segments": len(ramps),
        "axes_fitted": len(keys),
        "chunks_new": sum(len(s.chunks) for s in new.values()),
        "chunks_old": sum(len(s.chunks) for s in old.values()),
        "schedules_identical": sum(new[k] == old.get(k) for k in keys),
        "axes_fitted_old": len(old),
        "batch_ms": round(1e3 * t_new, 2),
        "batch_ms_old": round(1e3 * t_old, 2),
        "batch_ms_per_ramp_segment": round(per * t_new, 3),
        "batch_ms_per_ramp_segment_old": round(per * t_old, 3),
        "batch_old_over_new": round(t_old / max(t_new, 1e-9), 1),
        "alone_ms_per_ramp_segment": round(per * a_new, 3),
        "alone_ms_per_ramp_segment_old": round(per * a_old, 3),
        "alone_old_over_new": round(a_old / max(a_new, 1e-9), 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tol-us", type=float, default=1.0)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--cup", type=Path, default=None)
    ap.add_argument(
        "--whole-limit", type=int, default=2000, help="segments measured for option A's bytes"
    )
    ap.add_argument(
        "--cup-segments", type=int, default=2000, help="the cup's segments the fitter is timed on"
    )
    ap.add_argument("--repeats", type=int, default=3, help="timings: the best of this many")
    args = ap.parse_args()
    stream = print_like(args.seconds)
    out: dict[str, object] = {
        "tol_us": args.tol_us,
        "print_like": analyse(stream, args.tol_us, args.whole_limit),
    }
    fitter = {"print_like": fitter_time(stream, args.tol_us, args.repeats)}
    if args.cup is not None:
        z = np.load(args.cup)
        cup = SegmentBatch(z["ticks"], z["deltas"], z["ramps"])
        out["cup"] = analyse(cup, args.tol_us, args.whole_limit)
        fitter["cup"] = fitter_time(cup[: args.cup_segments], args.tol_us, args.repeats)
    out["fitter"] = fitter
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
