"""Link efficiency: wire bytes per move segment, the segment rate a 250000-baud UART
sustains, and the same motion as Marlin-style ASCII G-code for comparison.

Run: python bench/link.py [--layers N] [--seed S]

The stream is a synthetic print (until the planner's output can be fed in): per
layer a circular perimeter cut into 0.5-3 mm chords at 30-60 mm/s, a square
perimeter and a zig-zag infill whose straight lines are cut into 1-3 mm chords
with accelerating, cruising and decelerating segments (the ramp codes make speed
continuous; every polyline ends at rest), through the paper-simulation machine's
inverse kinematics at 400 steps/mm, extruder 95.5 steps/mm. ``measure`` takes any
SegmentBatch plus the Cartesian endpoints, so a planned fixture can be fed later.

Targets: <= 12 wire bytes per segment on average, >= 3x fewer bytes than ASCII.
Measured (this repository, default arguments: 8 layers, 27451 segments, 867 s of
motion): 5.21 wire bytes per segment (5.00 in payloads); 4800 segments/s sustainable
at 250000 baud (4820 measured through the simulated wire); ASCII G-code 49.8 bytes
per segment, ratio 9.5x. The bench takes about 6 s.
"""

from __future__ import annotations

import argparse
import itertools
import math

import numpy as np

from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.device.config import SimConfig
from firmware_protocol.messages import HOTEND, WaitHeater
from firmware_protocol.segments import (
    RAMP_TO_REST,
    SegmentBatch,
    SegmentContext,
    encode_segments,
    ramp_codes_from_speeds,
)

CLOCK_HZ = 100_000
BAUD = 250_000
E_PER_MM = 0.0333  # mm of 1.75 mm filament per mm of 0.4 x 0.2 mm line
ACCEL = 2000.0


def _polyline_profile(points: np.ndarray, v_max: float, rng, chord: tuple[float, float]) -> tuple:
    """Cut a polyline into chords; trapezoidal speed per straight side. Returns points, speeds at points."""
    out_pts = [points[:1]]
    out_v = [np.zeros(1)]
    for a, b in itertools.pairwise(points):
        length = float(np.linalg.norm(b - a))
        n = max(2, int(math.ceil(length / rng.uniform(*chord))))  # from rest to rest needs two
        s = np.linspace(0.0, length, n + 1)[1:]
        v_peak = min(v_max, math.sqrt(ACCEL * length))
        v = np.minimum.reduce(
            [np.full_like(s, v_peak), np.sqrt(2 * ACCEL * s), np.sqrt(2 * ACCEL * (length - s))]
        )
        out_pts.append(a + (b - a) * (s / length)[:, None])
        out_v.append(v)
    return np.vstack(out_pts), np.concatenate(out_v)


def synthetic_print(layers: int = 20, seed: int = 0) -> tuple[SegmentBatch, np.ndarray, np.ndarray]:
    """A synthetic print as segments; also the Cartesian endpoints (N+1, 3) and feed rates (N,) in mm/s."""
    rng = np.random.default_rng(seed)
    model = MachineModel.from_profile(load_profile("paper-simulation"))
    pts_all, v_all = [], []
    for layer in range(layers):
        z = 110.2 + 0.2 * layer
        r = rng.uniform(20, 70)
        n = int(2 * math.pi * r / rng.uniform(0.5, 3.0))
        ang = np.linspace(0, 2 * math.pi, n + 1)
        circle = np.stack([r * np.cos(ang), r * np.sin(ang), np.full(n + 1, z)], axis=1)
        v = rng.uniform(30, 60)
        speeds = np.full(n + 1, v)
        speeds[0] = speeds[-1] = 0.0  # from rest, to rest
        pts_all.append(circle)
        v_all.append(speeds)
        h = rng.uniform(15, 40)
        square = np.array([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z], [-h, -h, z]])
        p, s = _polyline_profile(square, rng.uniform(30, 60), rng, (1.0, 3.0))
        pts_all.append(p)
        v_all.append(s)
        ys = np.arange(-h + 1, h - 1, 0.45)
        side = np.where(np.arange(len(ys)) % 2 == 0, -(h - 1), h - 1)
        zig = np.repeat(np.stack([side, ys, np.full(len(ys), z)], axis=1), 2, axis=0)
        zig[1::2, 0] *= -1
        p, s = _polyline_profile(zig, 60.0, rng, (1.0, 3.0))
        pts_all.append(p)
        v_all.append(s)
    ticks_l, deltas_l, ramps_l, cart_l, feed_l = [], [], [], [], []
    e_pos = 0.0
    prev_end = None
    for pts, v in zip(pts_all, v_all):
        if prev_end is not None:  # a travel move to the next polyline, from rest to rest
            p, s = _polyline_profile(np.vstack([prev_end, pts[:1]]), 150.0, rng, (2.0, 3.0))
            pts = np.vstack([p, pts[1:]])
            v = np.concatenate([s, v[1:]])
            extrude = np.concatenate([np.zeros(len(p) - 1), np.ones(len(v) - len(p))])
        else:
            extrude = np.ones(len(v) - 1)
        keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
        pts, v, extrude = pts[keep], v[keep], extrude[keep[1:]]
        prev_end = pts[-1]
        seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        v0, v1 = v[:-1], v[1:]
        dt = 2 * seg_len / np.maximum(v0 + v1, 1e-9)
        steps = model.steps(model.ik(pts, path=True))
        e_mm = e_pos + np.concatenate([[0.0], np.cumsum(seg_len * E_PER_MM * extrude)])
        e_pos = float(e_mm[-1])
        e_steps = np.rint(e_mm * 95.5).astype(np.int64)
        ticks_l.append(np.maximum(1, np.rint(dt * CLOCK_HZ)).astype(np.int64))
        deltas_l.append(np.column_stack([np.diff(steps, axis=0), np.diff(e_steps)]))
        ramps = ramp_codes_from_speeds(v0, v1)
        ramps[-1] = RAMP_TO_REST
        ramps_l.append(ramps)
        cart_l.append(pts if not cart_l else pts[1:])
        feed_l.append((v0 + v1) / 2)
    batch = SegmentBatch(np.concatenate(ticks_l), np.vstack(deltas_l), np.concatenate(ramps_l))
    return batch, np.vstack(cart_l), np.concatenate(feed_l)


def marlin_ascii(cart: np.ndarray, e_mm: np.ndarray, feed_mm_s: np.ndarray) -> bytes:
    """The same endpoints as Marlin G-code: ``N<n> G1 X.. Y.. Z.. E.. F..*<checksum>``, F only when it changes."""
    lines = []
    last_f = None
    for i in range(1, len(cart)):
        x, y, z = cart[i]
        f = round(feed_mm_s[i - 1] * 60)
        body = f"N{i} G1 X{x:.3f} Y{y:.3f} Z{z:.3f} E{e_mm[i]:.5f}" + (
            f" F{f}" if f != last_f else ""
        )
        last_f = f
        cs = 0
        for ch in body.encode():
            cs ^= ch
        lines.append(f"{body}*{cs}\n")
    return "".join(lines).encode()


def measure(
    batch: SegmentBatch, cart: np.ndarray, feed_mm_s: np.ndarray, *, e_steps_per_mm: float = 95.5
) -> dict:
    """Bytes and rates for one stream (``cart``: (N+1, 3) Cartesian endpoints)."""
    n = len(batch)
    payload, _ = encode_segments(batch, SegmentContext())
    link = open_embedded(config=SimConfig(queue_capacity=512, overtravel_steps=10**9))
    link.queue_segments(batch)
    link.wait_idle()
    wire = link.counters.bytes_sent
    # link-bound rate: a queue that holds everything, held by a heater wait that never ends, so
    # only the wire limits delivery; the status reply comes after every segment was accepted
    link2 = open_embedded(config=SimConfig(queue_capacity=n + 8, overtravel_steps=10**9))
    link2.send(WaitHeater(HOTEND, 0))
    t0 = link2.now()
    link2.queue_segments(batch)
    link2.request_status(timeout=60)
    measured_rate = n / (link2.now() - t0)
    e_mm = np.concatenate([[0.0], np.cumsum(batch.deltas[:, 3])]) / e_steps_per_mm
    ascii_bytes = len(marlin_ascii(cart, e_mm, feed_mm_s))
    return {
        "segments": n,
        "payload_bytes_per_segment": len(payload) / n,
        "wire_bytes_per_segment": wire / n,
        "sustainable_segments_per_s": BAUD / 10 / (wire / n),
        "measured_segments_per_s": measured_rate,
        "ascii_bytes_per_segment": ascii_bytes / n,
        "ascii_ratio": ascii_bytes / wire,
        "motion_s": float(batch.ticks.sum()) / CLOCK_HZ,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layers", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    batch, cart, feed = synthetic_print(args.layers, args.seed)
    r = measure(batch, cart, feed)
    need = r["segments"] / r["motion_s"]
    rows = [
        ("segments (synthetic print)", f"{r['segments']}"),
        ("motion time", f"{r['motion_s']:.1f} s ({need:.0f} segments/s needed on average)"),
        ("payload bytes / segment", f"{r['payload_bytes_per_segment']:.2f}"),
        (
            "wire bytes / segment (framing, retransmit-free)",
            f"{r['wire_bytes_per_segment']:.2f}  (target <= 12)",
        ),
        ("segments/s at 250000 baud (25000 B/s / bytes)", f"{r['sustainable_segments_per_s']:.0f}"),
        ("segments/s measured on the simulated wire", f"{r['measured_segments_per_s']:.0f}"),
        ("Marlin ASCII bytes / segment (N.. G1 ..*cs)", f"{r['ascii_bytes_per_segment']:.2f}"),
        ("ASCII / binary", f"{r['ascii_ratio']:.2f}x  (target >= 3x)"),
    ]
    width = max(len(a) for a, _ in rows)
    for a, b in rows:
        print(f"{a:<{width}}  {b}")


if __name__ == "__main__":
    main()
