"""Where ramps are cut so each piece's step schedule fits one frame (PROTOCOL.md 5.5).

A device with a step engine steps a ramp's axis from the schedule block the host sends with
the segment. A long ramp (many steps, from or to rest) can need a block longer than a frame
carries, or more chunks on one axis than a block holds; without its block the axis falls back
to the device's own stepping of the profile, which on the AVR is the 400 us tick's and holds
far less than the engine's rate. Such a segment is cut here, in the plan, into equal-time
pieces: each piece takes the steps the device's own rule has issued by its cut
(``floor(|n| p + 1/2)``) and the speeds at its ends (speed is linear in time), so the line in
joint space and the timing are the segment's. The cut is decided by fitting each piece's
schedules as the link will (the same fitter, tolerance and frame budget): what is cut fits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_protocol.ramp_profile import RAMP_CONSTANT, ramp_codes_from_speeds, steps_done
from firmware_protocol.segment_split import block_sizes
from firmware_protocol.segments import SEGMENT_MAX_BYTES, SegmentBatch, peak_step_rates
from firmware_protocol.step_schedule import reciprocal_table

#: a segment and its schedule block fit a frame of this many payload bytes (the AVR asks
#: for 120, IDENT ``max_payload``); every device gets the same cuts for the same plan
BLOCK_FRAME_BYTES = 120
#: a segment is cut into at most this many pieces (each at least the shortest segment)
MAX_PIECES = 16


@dataclass(frozen=True)
class BlockLimits:
    """What a device that steps ramps from schedule blocks takes: CPU cycles per device
    tick, its schedule tolerance (cycles), the peak rate of an axis it steps without a
    block (STEPPING: a ramp faster than this on any axis needs its block) and the payload
    bytes a segment's block may take."""

    cycles_per_tick: int
    tolerance_cycles: float
    profile_step_rate: float
    block_bytes: int = BLOCK_FRAME_BYTES - SEGMENT_MAX_BYTES

    @classmethod
    def for_device(
        cls,
        cpu_hz: int,
        clock_hz: int,
        tolerance_cycles: float,
        max_payload: int,
        profile_step_rate: float,
    ) -> BlockLimits:
        """The limits of a device announcing these (IDENT, CAPS, STEPPING)."""
        frame = min(int(max_payload), BLOCK_FRAME_BYTES)
        return cls(
            int(cpu_hz) // int(clock_hz),
            float(tolerance_cycles),
            float(profile_step_rate),
            frame - SEGMENT_MAX_BYTES,
        )


def equal_pieces(
    ticks: int, delta: np.ndarray, v_start: float, v_end: float, code: int, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The segment in ``k`` pieces of (nearly) equal time: their end times as fractions of
    the segment (``tau``, (k,)), durations in ticks (k,), steps (k, 4) and speeds at their
    ends (k + 1,: start, cuts, end)."""
    cut = np.rint(np.arange(1, k + 1) * (ticks / k)).astype(np.int64)
    cut[-1] = ticks
    tau = cut / ticks
    done = np.array([steps_done(delta, code, float(t)) for t in tau[:-1]] + [np.asarray(delta)])
    steps = np.diff(done, axis=0, prepend=np.zeros((1, delta.shape[0]), np.int64))
    speeds = np.concatenate([[v_start], v_start + (v_end - v_start) * tau])
    return tau, np.diff(cut, prepend=0), steps, speeds


def _fit(batch: SegmentBatch, limits: BlockLimits, table: np.ndarray) -> np.ndarray:
    """(n,) bool: each segment's schedule block fits ``limits``."""
    sizes = block_sizes(batch, limits.cycles_per_tick, limits.tolerance_cycles, table)
    return np.asarray((sizes >= 0) & (sizes <= limits.block_bytes))


def block_cuts(
    ticks: np.ndarray,
    delta: np.ndarray,
    v_start: np.ndarray,
    v_end: np.ndarray,
    limits: BlockLimits,
    min_ticks: int,
    clock_hz: int,
    max_step_rate: float | None = None,
) -> dict[int, int]:
    """The ramps of a batch faster than the device steps without a block
    (``limits.profile_step_rate``) whose schedule blocks would not fit ``limits``, with the number
    of equal-time pieces (2 or more, each at least ``min_ticks`` and at most ``max_step_rate``
    at its peak) that makes every piece's block fit. A ramp that no such cut fits is left
    whole (its axes then fall back to the device's own stepping)."""
    codes = ramp_codes_from_speeds(v_start, v_end)
    table = reciprocal_table(limits.cycles_per_tick)
    out: dict[int, int] = {}
    peak = peak_step_rates(SegmentBatch(ticks, delta, codes), clock_hz).max(axis=1)
    fast = np.flatnonzero((codes != RAMP_CONSTANT) & (peak > limits.profile_step_rate))
    if not fast.size:
        return out
    whole = _fit(SegmentBatch(ticks[fast], delta[fast], codes[fast]), limits, table)
    for i in fast[~whole].tolist():
        t, d = int(ticks[i]), delta[i]
        for k in range(2, min(MAX_PIECES, t // max(1, min_ticks)) + 1):
            _, pt, ps, speeds = equal_pieces(
                t, d, float(v_start[i]), float(v_end[i]), int(codes[i]), k
            )
            pieces = SegmentBatch(pt, ps, ramp_codes_from_speeds(speeds[:-1], speeds[1:]))
            if (
                max_step_rate is not None
                and (peak_step_rates(pieces, clock_hz) > max_step_rate).any()
            ):
                continue
            if _fit(pieces, limits, table).all():
                out[i] = k
                break
    return out
