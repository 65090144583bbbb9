"""The firmware's stack: the canary word at the end of static RAM, checked every main-loop
turn, and the static worst case (call graph + -fstack-usage) against a margin."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cdprhost.sim import avr_device
from firmware_protocol.codes import ErrorCode
from firmware_protocol.messages import Enable, Error, Flag, SetHeater
from tests.conformance.device import RawHost

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(120)
def test_a_smashed_canary_goes_through_the_one_shutdown_path(avr_built, tmp_path):
    cmd = avr_device.harness_command(stats=str(tmp_path / "stats.json"))
    proc = subprocess.Popen(
        [*cmd, "--smash-canary-after", "2.0"], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None
        h = RawHost(proc.stdout.readline().strip())
        try:
            h.hello()
            h.send(Enable(0b0111), SetHeater(0, 500))
            h.wait_for(lambda: h.of(Error, code=ErrorCode.STACK_OVERFLOW), 30, "STACK_OVERFLOW")
            st = h.status()
        finally:
            h.close()
    finally:
        proc.terminate()
        proc.wait(30)
    assert st.flags & Flag.FAULT and st.last_error == ErrorCode.STACK_OVERFLOW
    assert st.hotend_target_dc == 0  # heaters off
    assert st.enabled_mask == 0b0111  # the effector held, as every shutdown does


def test_the_static_worst_case_stack_keeps_its_margin(avr_built):
    """firmware/tools/stack_usage.py: fails (exit 1) when the margin is not kept."""
    # the build the tests run (the engine's under CDPRHOST_STEP_ENGINE=1), with its frames
    cflags = ["--cflags=-DSTEP_ENGINE=1"] if avr_device.STEP_ENGINE else []
    tool = [sys.executable, str(ROOT / "firmware" / "tools" / "stack_usage.py")]
    proc = subprocess.run(
        [*tool, "--elf", str(avr_device.BOARD_ELF), *cflags],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "worst case" in proc.stdout


def test_the_step_engine_build_keeps_the_margin_with_its_own_frames(tmp_path):
    # `make stack` compiles the frames with the build's options: the engine build's own
    # frames are larger than the default build's, so reading its ELF with the default
    # frames under-counts its worst case.
    missing = avr_device.toolchain_missing()
    if missing:
        pytest.skip(missing)
    build = tmp_path / "engine"
    proc = subprocess.run(
        ["make", "-s", f"BUILD={build}", "EXTRA_CFLAGS=-DSTEP_ENGINE=1", "stack"],
        cwd=ROOT / "firmware",
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "worst case" in proc.stdout
    # the same ELF read with the default build's frames is not what the tool reports
    plain = subprocess.run(
        [
            sys.executable,
            str(ROOT / "firmware" / "tools" / "stack_usage.py"),
            "--elf",
            str(build / "cdpr.elf"),
            "--margin",
            "0",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert _worst(plain.stdout) < _worst(proc.stdout), (plain.stdout, proc.stdout)


def _worst(report: str) -> int:
    return int(report.split("worst case ", 1)[1].split(" B", 1)[0])
