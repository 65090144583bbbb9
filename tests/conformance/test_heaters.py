"""The heaters on both devices (the Python model and the AVR firmware in simavr) against the
one plant of ``firmware_protocol/device/thermal_plant.py``: first order with dead time,
heat loss and thermistor noise.

- A relay autotune finds the gains the in-process plant model finds (within 15 %), with a
  period in the range of a real hotend (20-60 s).
- Thermal protection fires within Marlin's default times (firmware/src/config.h, and
  ``HOTEND_MODEL``): heating that does not rise by 2 C within the 40 s watch period; a
  temperature more than 4 C below its target for the 40 s runaway period; a thermistor
  that opens (MINTEMP) or shorts (MAXTEMP): at the next readings (within 1 s).

Times are device times: the STATUS clock (100 kHz) read as the fault is reported. The
tests start a warm hotend (``hotend_start_c``) where the heat-up itself is not what they
check, so the AVR, which simavr runs at about real time, is not kept a minute heating.
"""

from __future__ import annotations

import math

import pytest

from firmware_protocol.device.heaters import HOTEND_MODEL, Heater
from firmware_protocol.messages import (
    Autotune,
    Error,
    ErrorCode,
    Event,
    EventCode,
    Flag,
    SetHeater,
    Status,
)

pytestmark = pytest.mark.timeout(600)

CLOCK_HZ = 100_000
#: Python device speed-ups; the AVR runs simavr as fast as it can whatever it is given
FAST = "40"
TIMED = "4"  # where the host samples the device's clock by its STATUS replies


def _clock_s(h) -> float:
    return h.status().clock / CLOCK_HZ


def _model_tune(start_c: float, target_c: float, cycles: int) -> tuple[float, float, float]:
    """The gains the plant model's own relay autotune finds (in-process, no device)."""
    heater = Heater(HOTEND_MODEL)
    heater.warm_start(start_c)
    heater.start_tune(target_c, cycles, 0.0)
    t = 0.0
    while heater.tune is not None:
        t += 1.0
        heater.advance(t)
        assert t < 1200, "the model's autotune did not end"
    assert heater.tuned is not None and heater.tuned.result is not None, heater.tuned
    g = heater.tuned.result
    return g.kp, g.ki, g.kd


def test_autotune_finds_a_real_hotends_gains_on_both_devices(device_factory, host_factory):
    """M303 at 210 C, 3 cycles, reported and applied: the device's gains within 15 % of the plant model's, and the
    relay period 2 kp / ki in 20-60 s (the model finds kp 11, ki 0.8, kd 37: 27 s)."""
    dev = device_factory("--speedup", FAST, "--faults", "hotend_start_c=200")
    h = host_factory(dev.path)
    h.hello()
    h.send(Autotune(0, 2100, 3))
    ev = h.wait_for(
        lambda: h.of(Event, code=EventCode.AUTOTUNE_DONE) or h.of(Error),
        timeout=500,
        what="AUTOTUNE_DONE",
    )
    assert isinstance(ev, Event), ev
    heater, *wire = ev.values
    kp, ki, kd = (v / 1000.0 for v in wire)
    assert heater == 0
    period = 2.0 * kp / ki
    assert 20.0 <= period <= 60.0, (kp, ki, kd, period)
    ref = _model_tune(200.0, 210.0, 3)
    for name, got, want in zip(("kp", "ki", "kd"), (kp, ki, kd), ref, strict=True):
        assert math.isclose(got, want, rel_tol=0.15), (name, got, want)
    st = h.status()
    assert st.hotend_target_dc == 0 and not st.flags & Flag.FAULT


def test_heating_that_does_not_rise_fails_within_the_watch_period(device_factory, host_factory):
    """The element is dead from the start: no 2 C rise within WATCH_TEMP_PERIOD (40 s) is a
    THERMAL_RUNAWAY, reported at 40 s (not before) and within one second after it."""
    dev = device_factory("--speedup", TIMED, "--faults", "heater_fail_after=0")
    h = host_factory(dev.path)
    h.hello()
    t_set = _clock_s(h)
    h.send(SetHeater(0, 2000))
    err = h.wait_for(
        lambda: h.of(Error, code=ErrorCode.THERMAL_RUNAWAY), timeout=120, what="THERMAL_RUNAWAY"
    )
    t_err = _clock_s(h)
    assert err.axis == 0
    assert HOTEND_MODEL.watch_period_s - 0.5 <= t_err - t_set <= HOTEND_MODEL.watch_period_s + 1.5
    assert h.status().hotend_target_dc == 0


def test_a_temperature_that_falls_away_is_a_runaway_after_its_period(device_factory, host_factory):
    """A warm hotend holds 200 C, then its element fails (device time 3 s): once the
    reading is more than 4 C below the target, 40 s (THERMAL_PROTECTION_PERIOD) later it
    is a THERMAL_RUNAWAY. The host watches the reading in the STATUS replies; the
    thermistor's noise (and the ADC's steps on the AVR) can dip a reading below the line
    early and back: the period runs from the start of the last stretch below it."""
    dev = device_factory("--speedup", TIMED, "--faults", "hotend_start_c=200,heater_fail_after=3")
    h = host_factory(dev.path)
    h.keepalive = 0.05
    h.hello()
    h.send(SetHeater(0, 2000))
    limit = 2000 - round(HOTEND_MODEL.runaway_hysteresis_c * 10)

    err = h.wait_for(
        lambda: h.of(Error, code=ErrorCode.THERMAL_RUNAWAY), timeout=120, what="THERMAL_RUNAWAY"
    )
    # the error carries no clock: it came between the last STATUS before it and the
    # clock read just after (on a loaded machine the host may read that one late)
    at = next(i for i, m in enumerate(h.reports) if m is err)
    seen = [m for m in h.reports[:at] if isinstance(m, Status)]  # status() drops them
    t_after = _clock_s(h)
    below_since = None
    for m in seen:
        if m.hotend_target_dc:
            if m.hotend_dc >= limit:
                below_since = None
            elif below_since is None:
                below_since = m.clock / CLOCK_HZ
    assert below_since is not None, "no STATUS showed the reading below target - 4 C"
    assert err.axis == 0
    t_before = seen[-1].clock / CLOCK_HZ
    period = HOTEND_MODEL.runaway_period_s
    # the STATUS that first showed it came up to a sampling interval after the reading
    assert t_before - below_since <= period + 1.5, (t_before, below_since)
    assert t_after - below_since >= period - 1.5, (t_after, below_since)


@pytest.mark.parametrize(
    "fault, code",
    [
        ("thermistor_open_after", ErrorCode.THERMAL_RUNAWAY),
        ("thermistor_short_after", ErrorCode.OVERTEMP),
    ],
)
def test_a_thermistor_that_opens_or_shorts_is_caught_at_once(
    device_factory, host_factory, fault, code
):
    """Heating, the thermistor opens (reads -20 C: MINTEMP) or shorts (reads 355 C:
    MAXTEMP) at device time 2 s: the fault within a second, the heater off."""
    dev = device_factory("--speedup", TIMED, "--faults", f"{fault}=2")
    h = host_factory(dev.path)
    h.hello()
    h.send(SetHeater(0, 2000))
    err = h.wait_for(lambda: h.of(Error, code=code), timeout=30, what=str(code))
    t_err = _clock_s(h)
    assert err.axis == 0
    assert 2.0 <= t_err <= 3.0
    st = h.status()
    assert st.hotend_target_dc == 0 and st.flags & Flag.FAULT


def test_the_plant_has_its_dead_time_its_noise_and_a_real_heat_up():
    """The model alone (no device): at full power nothing reaches the thermistor for the
    dead time (6 s), then it heats; 200 C in 60-90 s (an E3D V6 class hotend); the
    reading's noise about 0.3 C."""
    heater = Heater(HOTEND_MODEL)
    heater.set_target(250.0, 0.0)
    t, reached_200 = 0.0, None
    readings = []
    while reached_200 is None:
        t = round(t + 0.1, 1)
        heater.advance(t)
        if t < HOTEND_MODEL.plant.dead_time_s - 0.2:
            assert heater.temp == pytest.approx(HOTEND_MODEL.ambient_c), t
            readings.append(heater.reading)
        if heater.reading >= 200.0:
            reached_200 = t
        assert t < 300
    assert 60.0 <= reached_200 <= 90.0
    mean = sum(readings) / len(readings)
    sd = math.sqrt(sum((r - mean) ** 2 for r in readings) / len(readings))
    assert 0.2 <= sd <= 0.4
