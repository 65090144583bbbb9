"""Protocol 3.3's STEP_BUDGET on both devices: a device whose axes share a budget of steps
says so after STEPPING in a 3.3 session (none to a 3.2 host, none from a device without
one), and refuses a segment whose axes add up to more (STEP_RATE, axis 4) before any of
it moves."""

from __future__ import annotations

import pytest

from firmware_protocol.codes import ALL_AXES
from firmware_protocol.messages import (
    Caps,
    Error,
    ErrorCode,
    Flag,
    GetCaps,
    Segment,
    StepBudget,
    Stepping,
)

pytestmark = pytest.mark.timeout(300)

#: the Python device is told a budget; the AVR announces its build's (the step engine's)
PYTHON_BUDGET = 80_000
PYTHON_ARGS = ["--max-step-rate", "30000", "--total-step-rate", str(PYTHON_BUDGET)]


def _announced(h, minor: int | None = None) -> tuple[int, StepBudget | None]:
    ident = h.hello(minor=minor)
    h.send(GetCaps())
    h.wait_for(lambda: h.of(Caps), what="CAPS")
    h.status()  # answered after anything GET_CAPS brought
    return ident.max_step_rate, h.of(StepBudget)


def test_a_budget_is_announced_in_a_3_3_session_and_a_segment_over_it_is_refused(
    kind, device_factory, host_factory
):
    dev = device_factory(*(PYTHON_ARGS if kind == "python" else []))
    h = host_factory(dev.path)
    rate, budget = _announced(h)
    assert h.of(Stepping) is not None
    if budget is None:
        assert kind == "avr"  # a build without one (the default's tick: its rate is the mix's)
        pytest.skip("this AVR build has no step budget (the step engine's build has)")
    if kind == "python":
        assert budget.total_step_rate == PYTHON_BUDGET
    assert budget.total_step_rate >= rate
    each = budget.total_step_rate // 4 + 500  # four axes in step, just over it in all
    if each > rate:
        pytest.skip(f"a budget of {budget.total_step_rate} never binds at {rate} an axis")
    d = each * 1000 // 100_000  # steps in a 10 ms segment
    h.send(Segment(1000, (d, d, d, d), -1, ()))
    err = h.wait_for(lambda: h.of(Error), what="an ERROR")
    assert (err.code, err.segment, err.axis) == (ErrorCode.STEP_RATE, 1, ALL_AXES)
    assert err.value == pytest.approx(4 * d * 100, rel=0.01)
    st = h.status()
    assert st.flags & Flag.FAULT and st.motion_ticks == 0 and st.steps == (0, 0, 0, 0)


def test_a_3_2_session_gets_no_budget(kind, device_factory, host_factory):
    dev = device_factory(*(PYTHON_ARGS if kind == "python" else []))
    h = host_factory(dev.path)
    _, budget = _announced(h, minor=2)
    assert h.of(Stepping) is not None and budget is None
