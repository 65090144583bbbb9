"""The printer service runs above its front ends when the system allows (a busy machine waits
for the print), and says what it could do when it may not."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from cdprhost.service import priority


def _in_child(code: str, env: dict[str, str] | None = None) -> str:
    run = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **(env or {})},
    )
    return run.stdout


CHILD = (
    "import os; from cdprhost.service.priority import raise_priority; "
    "said = raise_priority(); print(os.getpriority(os.PRIO_PROCESS, 0)); print(said)"
)


@pytest.mark.skipif(os.geteuid() != 0, reason="only the super-user may lower a nice value")
def test_the_service_lowers_its_nice_value_when_allowed():
    start = os.getpriority(os.PRIO_PROCESS, 0)
    now, said = _in_child(CHILD).splitlines()
    assert int(now) == max(-20, start - priority.DEFAULT_STEP)
    assert said.startswith(f"nice {now} (started at {start})")


def test_the_step_can_be_set_or_turned_off():
    start = os.getpriority(os.PRIO_PROCESS, 0)
    now, said = _in_child(CHILD, {priority.ENV: "0"}).splitlines()
    assert int(now) == start and "left as started" in said


def test_not_allowed_it_runs_as_started_and_says_why(monkeypatch):
    def refuse(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(priority.os, "setpriority", refuse)
    said = priority.raise_priority(5)
    assert "not allowed to run above the front ends" in said and "ulimit -e" in said


def test_the_rlimit_floor_is_tried_after_the_full_step(monkeypatch):
    tried: list[int] = []

    def only_down_to_minus_two(_which, _who, value):
        tried.append(value)
        if value < -2:
            raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(priority.os, "getpriority", lambda *_a: 0)
    monkeypatch.setattr(priority.os, "setpriority", only_down_to_minus_two)
    monkeypatch.setattr(priority, "lowest_allowed", lambda: -2)
    assert priority.raise_priority(10).startswith("nice -2 (started at 0)")
    assert tried == [-10, -2]
