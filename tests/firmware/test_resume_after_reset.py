"""A reset at connect made harmless (issue 30, item 3), on the AVR firmware booted through
the Mega 2560's stk500v2 bootloader in simavr.

Opening a Mega's port raises DTR, whose auto-reset pulls the RESET pin; the harness does it
on SIGUSR1 (a pty carries no DTR). The firmware keeps its counters through the reset, holds
the drivers, and announces both in BOOT; the host listens for that BOOT before its first
HELLO (a HELLO reaching the bootloader during its wait would hold it in its programming
loop for about 5 s more), and ``print --resume`` continues from the exact segment.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cdprhost.job.resume import ResumePoint, resume_path_for
from cdprhost.link import HostLink
from cdprhost.link.serial_port import open_serial
from cdprhost.sim import avr_device
from firmware_protocol.codes import BootCause
from firmware_protocol.messages import Boot
from tests.conformance.device import RawHost
from tests.e2e.processes import printing_point, signal_service, square_part
from tests.e2e.reset_resume import ONE_MOVE, compare

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux", reason="pseudo-terminals as on Linux"),
    pytest.mark.skipif(
        not avr_device.BOOTLOADER_HEX.exists(),
        reason="the stk500v2 bootloader is missing: apt-get install -y arduino-core-avr",
    ),
    pytest.mark.timeout(600),
]

SPEEDUP = 4.0  # simavr manages about 3x real time here
LAYERS = 3
HELD = 0b0111  # the three modules; the extruder's driver is off between its moves


class Board:
    """The harness with the bootloader, its record and figures; powered on."""

    def __init__(self, tmp: Path, name: str):
        self.record = tmp / f"{name}.jsonl"
        self.stats_path = tmp / f"{name}-stats.json"
        cmd = avr_device.harness_command(
            speedup=SPEEDUP,
            record=str(self.record),
            stats=str(self.stats_path),
            bootloader=avr_device.BOOTLOADER_HEX,
        )
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.path = self.proc.stdout.readline().strip()
        assert self.path.startswith("/dev/"), self.path

    def boot(self) -> Boot:
        """The firmware's next BOOT, the line silent until it comes (the bootloader first)."""
        host = RawHost(self.path)
        try:
            return host.wait_for(
                lambda: next((m for m in host.urgent if isinstance(m, Boot)), None), 30, "BOOT"
            )
        finally:
            host.close()

    def rows(self) -> list[dict]:
        text = self.record.read_text() if self.record.exists() else ""
        return [r for r in map(json.loads, text.splitlines()) if "error" not in r]

    def settled(self) -> list[dict]:
        """The record once motion has stopped (the harness writes each row at once)."""
        last: list[dict] = []
        for _ in range(60):
            now = self.rows()
            if now and now == last:
                return now
            last = now
            time.sleep(0.5)
        raise AssertionError("the record kept growing")

    def stop(self) -> dict:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(30)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        return json.loads(self.stats_path.read_text())


@pytest.fixture
def board(avr_built, tmp_path):
    made: list[Board] = []

    def power_on(name: str) -> Board:
        b = Board(tmp_path, name)
        made.append(b)
        return b

    yield power_on
    for b in made:
        if b.proc.poll() is None:
            b.stop()


def _print(gcode: Path, port: str, state: Path, *extra: str) -> subprocess.Popen[str]:
    env = {**os.environ, "CDPRHOST_STATE": str(state)}
    cmd = [sys.executable, "-m", "cdprhost", "print", str(gcode), "--profile", "paper-prototype"]
    return subprocess.Popen(
        [*cmd, "--port", port, *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def test_a_reset_after_a_killed_host_then_resume_continues_from_the_exact_segment(board, tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=LAYERS)
    clean_board = board("clean")
    clean_board.boot()
    host = _print(gcode, clean_board.path, tmp_path / "clean-state")
    out, err = host.communicate(timeout=400)
    assert host.returncode == 0, out + err
    clean_board.stop()
    clean = clean_board.rows()

    chip = board("chip")
    chip.boot()
    state = tmp_path / "state"
    host = _print(gcode, chip.path, state)
    printing_point(gcode, state, segments=150)
    signal_service(chip.path, state, signal.SIGKILL)
    host.communicate(timeout=60)
    first = chip.settled()  # the firmware's host watchdog stopped the motion
    point = ResumePoint.load(resume_path_for(gcode, state / "jobs"))
    assert len(first) >= point.device_segment - point.first_segment + 1
    chip.proc.send_signal(signal.SIGUSR1)  # the DTR auto-reset of the next connect
    boot = chip.boot()  # through the bootloader
    assert boot.cause == BootCause.EXTERNAL_RESET and boot.prev_valid, boot
    assert boot.prev_segments_done >= point.device_segment

    report = tmp_path / "resume.json"
    host = _print(gcode, chip.path, state, "--resume", "--yes", "--json", str(report))
    out, err = host.communicate(timeout=400)
    assert host.returncode == 0, out + err
    stats = chip.stop()
    result = json.loads(report.read_text())
    assert result["status"] == "completed" and result["last_layer"] == LAYERS
    assert any("reset before this connect (external reset" in n for n in result["notices"])
    assert any("kept through the reset" in n for n in result["notices"]), result["notices"]
    # the drivers enabled before the reset stayed enabled until the host's first byte after it
    assert stats["resets"] == 1 and stats["enable_released_mask"] & HELD == 0, stats
    same = compare(clean, first, chip.rows()[len(first) :])
    assert same.prefix_equal and same.approach_found and same.last_equal, same
    assert same.filament_equal, same
    # every segment after the move the device stopped in is the uninterrupted print's: module
    # steps, extruder increment and duration; that move's rest (if it stopped moving) was
    # planned again from rest
    assert same.replaced <= ONE_MOVE and same.resumed - same.tail_equal <= ONE_MOVE + 2, same


def test_a_connect_that_resets_the_board_waits_for_its_bootloader_and_says_so(board):
    """The order of a real first open: the port opens (DTR rises: the reset), the host
    listens while the bootloader waits, the firmware's BOOT comes, then HELLO."""
    chip = board("idle")
    chip.boot()
    transport = open_serial(chip.path)
    transport.reset_at_open = True  # what opening a Mega's ttyACM reports (HUPCL was set)
    chip.proc.send_signal(signal.SIGUSR1)
    link = HostLink(transport)
    try:
        link.handshake()
        boot = link.boot
        assert boot is not None and boot.cause == BootCause.EXTERNAL_RESET and boot.prev_valid
        assert link.request_status().segments_done == 0
    finally:
        link.close()
    stats = chip.stop()
    assert stats["resets"] == 1


def test_without_a_record_the_resume_is_refused(board, tmp_path):
    """A power loss: the board comes back without its record; --resume names the layer."""
    gcode = square_part(tmp_path / "part.gcode", layers=LAYERS)
    chip = board("first")
    chip.boot()
    state = tmp_path / "state"
    host = _print(gcode, chip.path, state)
    printing_point(gcode, state, segments=150)
    signal_service(chip.path, state, signal.SIGKILL)
    host.communicate(timeout=60)
    chip.stop()
    again = board("again")  # powered on: RAM lost
    assert again.boot().cause == BootCause.POWER_ON
    report = tmp_path / "resume.json"
    host = _print(gcode, again.path, state, "--resume", "--yes", "--json", str(report))
    out, err = host.communicate(timeout=120)
    result = json.loads(report.read_text())
    assert host.returncode == 1 and result["status"] == "refused", out + err
    assert "--resume-from-layer" in result["reason"]
    assert not again.rows()  # nothing moved
