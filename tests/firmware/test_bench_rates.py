"""The helpers of bench/firmware_rates.py: the batches its rate search streams and how a
point is judged (pure), and that the step interrupts it profiles are the build's own, for
either engine (one short simavr run a rate; the search itself is a benchmark)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdprhost.sim import avr_device
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segments import peak_step_rates
from tests.conftest import load_script

BENCH = Path(__file__).resolve().parents[2] / "bench" / "firmware_rates.py"


@pytest.fixture(scope="module")
def fr():
    return load_script(BENCH, "firmware_rates")


OUT_OF_STEP = "three modules out of step, extruder running"


@pytest.mark.parametrize("rate", [1_000, 11_500, 33_000, 100_000])
def test_out_of_step_modules_differ_by_a_step_a_segment_at_any_rate(fr, rate):
    batch = fr.constant_batch(fr.rates_of(OUT_OF_STEP, rate))
    n = np.abs(batch.deltas[0, :3])
    assert n[0] > n[1] > n[2] > 0, n  # their edges drift across each other
    assert batch.deltas[0, 3] != 0  # the extruder runs


@pytest.mark.parametrize("config", ["one module alone", "a print's mix", OUT_OF_STEP])
def test_no_segment_peaks_above_r(fr, config):
    rate = 30_000
    rates = fr.rates_of(config, rate)
    for batch in (fr.constant_batch(rates), fr.ramp_batch(rates)):
        peak = peak_step_rates(batch, 100_000)
        assert peak.max() <= rate
        assert peak[:, 0].max() == rate  # and the busiest module reaches it


def test_ramps_reach_r_from_rest_and_end_at_rest(fr):
    batch = fr.ramp_batch([20_000, 15_000, 10_000, 2_000], cycles=2, steady=3)
    assert list(batch.ramps[:5]) == [0, RAMP_CONSTANT, RAMP_CONSTANT, RAMP_CONSTANT, 255]
    assert batch.deltas.sum(axis=0).tolist() == [0, 0, 0, 0]  # back and forth


def test_without_a_brake_the_points_are_steady_and_stop_at_rest(fr):
    rates = [20_000, 15_000, 10_000, 2_000]
    batch = fr.constant_batch(rates, n=6, brake=False)
    assert set(batch.ramps.tolist()) == {RAMP_CONSTANT}  # the step engine's own segments
    assert not batch.deltas[-1].any() and batch.deltas[-2].any()  # a stop, then rest
    assert peak_step_rates(batch, 100_000)[:, 0].max() == 20_000
    braked = fr.constant_batch(rates, n=6)
    assert len(braked) == 6 and braked.ramps[-1] != RAMP_CONSTANT


def test_edge_errors_count_missing_edges_and_measure_each_edge(fr):
    batch = fr.constant_batch([10_000, 0, 0, 0], n=2)
    ideal = fr.ideal_edges_us(batch, 0)
    cycles = np.round(ideal * 16).astype(np.int64)
    exact = np.stack([np.zeros_like(cycles), cycles], axis=1)
    err, missing = fr.edge_errors(exact, batch)
    assert missing == 0 and err.max() < 0.1
    late = exact.copy()
    late[3, 1] += 16 * 12  # one edge 12 us late
    err, _ = fr.edge_errors(late, batch)
    assert err.max() == pytest.approx(12, abs=0.1)
    _, missing = fr.edge_errors(exact[:-1], batch)
    assert missing == 1


def test_a_point_passes_only_within_every_limit(fr):
    good = {
        "record_exact": True,
        "worst_us": 9.9,
        "p99_us": 4.9,
        "edges_missing_or_extra": 0,
        "overruns": 0,
        "lost_steps": 0,
        "late_pulses": 0,
        "clock_slips": 0,
    }
    assert fr.passes(good) and fr.fail_reason(good) == ""
    for key, bad in [
        ("worst_us", 10.1),
        ("p99_us", 5.1),
        ("overruns", 1),
        ("late_pulses", 1),
        ("record_exact", False),
    ]:
        point = good | {key: bad}
        assert not fr.passes(point) and fr.fail_reason(point)


def test_isr_load_takes_the_idle_ticks_out(fr):
    point = {"isr_cycles": 600_000, "run_cycles": 2_000_000, "motion_cycles": 1_000_000}
    assert fr.isr_load_pct(point, 0.0) == 60.0
    assert fr.isr_load_pct(point, 0.1) == 50.0  # 1e6 idle cycles at 10 %


def test_edges_are_counted_per_axis(fr):
    batch = fr.constant_batch([10_000, 0, 5_000, 0], n=2)
    edges = np.array([[0, 1], [0, 2], [2, 3]])
    assert fr.axis_edge_counts(edges, batch) == ["2/150", "0/0", "1/75", "0/0"]


def test_builds_name_their_engine(fr):
    assert fr.default_build().engine == "default (tick DDA)"
    engine = fr.Build(1000, Path("e.elf"), Path("h"), fr.ENGINE_CFLAGS)
    assert engine.engine == "step engine"


@pytest.mark.parametrize("cflags", ["", "-DSTEP_ENGINE=1"])
def test_the_step_interrupts_load_grows_with_the_steps_on_either_engine(fr, cflags):
    # the step engine steps from Timer3 and Timer5: a profile of Timer1's vectors only
    # saw its tick, the same cycles at 4x the steps
    missing = avr_device.toolchain_missing()
    if missing:
        pytest.skip(missing)
    build = fr.variant(200_000, cflags)
    slow, fast = (
        fr.run_batch(build, fr.constant_batch([rate, 0, 0, 0], n=6)) for rate in (5_000, 20_000)
    )
    assert slow["passed"] and fast["passed"], (slow, fast)
    idle = fr.idle_isr_share(build)  # the session's idle ticks before and after the motion
    extra = (fr.isr_load_pct(fast, idle) - fr.isr_load_pct(slow, idle)) / 100
    edges = 5 * 150 + 75  # the extra edges at 20,000: 150 a 10 ms segment, the last half
    assert extra * fast["motion_cycles"] / edges > 60, (slow, fast)  # cycles an edge
