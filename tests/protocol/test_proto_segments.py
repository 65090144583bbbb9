"""Segment profile, step timing, and the segment coder."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from firmware_protocol.ramp_profile import (
    RAMP_CONSTANT,
    ends_at_rest,
    profile,
    ramp_codes_from_speeds,
    ramp_share,
    step_times,
    steps_done,
)
from firmware_protocol.segments import (
    SegmentBatch,
    SegmentContext,
    decode_segment,
    encode_segments,
    peak_step_rates,
)

ramp_st = st.integers(-1, 255)


def batches(max_n=40, max_delta=2**31 - 1):
    return st.integers(1, max_n).flatmap(
        lambda n: st.builds(
            SegmentBatch,
            hnp.arrays(np.int64, n, elements=st.integers(1, 2**32 - 1)),
            hnp.arrays(np.int64, (n, 4), elements=st.integers(-max_delta, max_delta)),
            hnp.arrays(np.int16, n, elements=ramp_st),
        )
    )


def decode_all(data: bytes, n: int, ctx: SegmentContext):
    pos, out = 0, []
    for _ in range(n):
        ticks, deltas, ramp, _, pos = decode_segment(data, pos, ctx)
        out.append((ticks, deltas, ramp))
    assert pos == len(data)
    return out


@given(batches())
def test_segment_batches_round_trip(batch):
    enc_ctx, dec_ctx = SegmentContext(), SegmentContext()
    data, offsets = encode_segments(batch, enc_ctx)
    assert offsets[0] == 0 and offsets[-1] == len(data)
    got = decode_all(data, len(batch), dec_ctx)
    assert [g[0] for g in got] == batch.ticks.tolist()
    assert [list(g[1]) for g in got] == batch.deltas.tolist()
    assert [g[2] for g in got] == batch.ramps.tolist()
    assert enc_ctx == dec_ctx


@given(batches(max_n=30, max_delta=5000), st.integers(1, 29))
def test_split_encoding_equals_whole(batch, cut):
    """Encoding in two calls (context carried) gives the same bytes as one call."""
    cut = min(cut, len(batch))
    whole, _ = encode_segments(batch, SegmentContext())
    ctx = SegmentContext()
    a, _ = encode_segments(batch[:cut], ctx)
    b, _ = encode_segments(batch[cut:], ctx)
    assert a + b == whole


def test_smooth_motion_is_compact():
    n = 200
    t = np.arange(n + 1) * 0.02
    pos = np.rint(
        np.stack([4000 * np.sin(t), 3000 * np.cos(t), -2000 * np.sin(0.5 * t), 30 * t], axis=1)
    )
    batch = SegmentBatch(np.full(n, 2000), np.diff(pos, axis=0))
    data, offsets = encode_segments(batch, SegmentContext())
    assert len(data) / n <= 5.0  # opcode + ~1 byte per slider; duration and extruder mostly omitted


def test_rejects_bad_batches():
    with pytest.raises(ValueError):
        SegmentBatch([0], [[1, 2, 3, 4]])
    with pytest.raises(ValueError):
        SegmentBatch([10, 10], [[1, 2, 3, 4]])
    with pytest.raises(ValueError):
        SegmentBatch([10], [[1, 2, 3, 4]], [300])


@given(st.integers(-3000, 3000), st.integers(1, 100_000), ramp_st)
def test_step_times_are_even_and_exact(n, ticks, ramp):
    times = step_times(n, ticks, ramp)
    assert len(times) == abs(n)
    if abs(n):
        assert np.all(np.diff(times) >= -1e-9) and times[0] >= 0 and times[-1] <= ticks
        # the step count at any instant matches steps_done
        for j in (0, abs(n) // 2, abs(n) - 1):
            tau = times[j] / ticks
            assert abs(int(steps_done([n, 0, 0, 0], ramp, tau + 1e-9)[0])) == j + 1
    assert int(steps_done([n, 0, 0, 0], ramp, 1.0)[0]) == n


@given(st.integers(1, 254))
def test_profile_speeds_follow_the_ramp(code):
    r = float(ramp_share(code))
    eps = 1e-6
    v0 = (profile(eps, code) - profile(0.0, code)) / eps
    v1 = (profile(1.0, code) - profile(1 - eps, code)) / eps
    assert v0 == pytest.approx(2 * r, abs=1e-4) and v1 == pytest.approx(2 - 2 * r, abs=1e-4)
    assert profile(1.0, code) == pytest.approx(1.0)


def test_ramp_codes_and_rest():
    codes = ramp_codes_from_speeds([0.0, 10.0, 10.0, 5.0, 0.0], [10.0, 0.0, 10.0, 15.0, 0.0])
    assert codes.tolist() == [0, 255, RAMP_CONSTANT, 64, RAMP_CONSTANT]
    assert ends_at_rest([[1, 0, 0, 0], [0, 0, 0, 0], [5, 5, 5, 5]], [255, -1, -1]).tolist() == [
        True,
        True,
        False,
    ]


def test_continuous_speed_across_segments():
    """Segments cut from one constant acceleration join with the same speed."""
    v = np.array([0.0, 100.0, 200.0, 300.0])  # steps/s at the boundaries, 0.1 s segments
    codes = ramp_codes_from_speeds(v[:-1], v[1:])
    deltas = (v[:-1] + v[1:]) / 2 * 0.1
    batch = SegmentBatch(
        np.full(3, 10_000),
        np.stack([deltas, 0 * deltas, 0 * deltas, 0 * deltas], axis=1).round(),
        codes,
    )
    r = ramp_share(batch.ramps)
    start = 2 * r * batch.deltas[:, 0] / 0.1
    end = (2 - 2 * r) * batch.deltas[:, 0] / 0.1
    assert np.allclose(end[:-1], start[1:], rtol=0.01)
    assert peak_step_rates(batch, 100_000)[:, 0] == pytest.approx(end, rel=1e-9)


@given(batches())
def test_the_scalar_encoder_makes_the_same_bytes(batch):
    from firmware_protocol.segments import encode_one_segment

    ctx_v, ctx_s = SegmentContext(), SegmentContext()
    data, _ = encode_segments(batch, ctx_v)
    one = b"".join(
        encode_one_segment(
            int(batch.ticks[i]), tuple(int(v) for v in batch.deltas[i]), int(batch.ramps[i]), ctx_s
        )
        for i in range(len(batch))
    )
    assert one == data and ctx_v == ctx_s
