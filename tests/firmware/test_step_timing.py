"""Every step edge of the AVR firmware at its exact time on the segment's profile
(PROTOCOL.md 5.1), within the late tolerance the device announces, at the step rate it
announces, with reversals and a last segment braking to rest."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from cdprhost.link import open_link
from firmware_protocol.segments import RAMP_CONSTANT, RAMP_TO_REST, SegmentBatch, step_times
from firmware_protocol.streams import expected_record

pytestmark = pytest.mark.usefixtures("avr_built")

CLOCK_HZ = 100_000
CYCLES_PER_UNIT = 160  # 16 MHz / 100 kHz: the step log is in cycles of the motion clock


def _batch(rates: list[int], n: int = 24, ticks: int = 1000) -> SegmentBatch:
    """``n`` segments at ``rates`` (steps/s per axis), reversing every third segment, the
    last braking to rest."""
    d = np.array(rates) * ticks // CLOCK_HZ
    sign = np.where((np.arange(n) // 3) % 2 == 0, 1, -1)
    deltas = np.outer(sign, d)
    deltas[-1] //= 2
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    ramps[-1] = RAMP_TO_REST
    return SegmentBatch(np.full(n, ticks), deltas, ramps)


#: four axes in step at the advertised rate; a print's mix (the modules at different
#: rates, their steps apart, the extruder slow) at 60 % of it, where the step
#: interrupts take about 70 % of the CPU (bench/firmware.py)
MIXES = {"in step": (1.0, 1.0, 1.0, 1.0), "a print's mix": (0.6, 0.45, 0.3, 0.06)}


def _ideal_us(batch: SegmentBatch, axis: int) -> np.ndarray:
    starts = np.concatenate([[0], np.cumsum(batch.ticks)[:-1]])
    parts = [
        starts[i] + step_times(int(batch.deltas[i, axis]), int(batch.ticks[i]), int(batch.ramps[i]))
        for i in range(len(batch))
    ]
    return np.concatenate(parts) * 1e6 / CLOCK_HZ


@pytest.mark.parametrize("mix", sorted(MIXES))
def test_steps_are_on_time(tmp_path, mix):
    log, record = tmp_path / "steps.txt", tmp_path / "record.jsonl"
    env = {**os.environ, "CDPR_SIM_STEP_LOG": str(log)}
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--firmware", "avr"]
    cmd += ["--speedup", "4", "--record", str(record)]
    dev = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    try:
        assert dev.stdout is not None
        link = open_link(dev.stdout.readline().strip())
        try:
            assert link.identity is not None and link.caps is not None
            rate, tolerance = link.identity.max_step_rate, link.caps.late_tolerance_us
            batch = _batch([int(rate * f) for f in MIXES[mix]])
            link.queue_segments(batch)
            link.wait_idle(120)
            link.request_status()
            health = link.health
        finally:
            link.close()
    finally:
        dev.send_signal(signal.SIGTERM)
        dev.wait(60)
    rows = [json.loads(line) for line in record.read_text().splitlines() if line.strip()]
    assert rows == expected_record(batch)
    edges = np.loadtxt(log, dtype=np.int64, ndmin=2)
    for axis in range(4):
        got = edges[edges[:, 0] == axis, 1] / (CYCLES_PER_UNIT / 10)  # us
        want = _ideal_us(batch, axis)
        assert got.shape == want.shape, (axis, got.shape, want.shape)
        err = got - want
        assert np.abs(err).max() <= tolerance, (axis, float(np.abs(err).max()))
        assert np.percentile(np.abs(err), 99) <= 10.0, (axis, float(np.percentile(np.abs(err), 99)))
    assert health is not None and health.late_pulses == 0
