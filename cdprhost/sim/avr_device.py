"""`cdprhost sim-device --firmware avr`: the C firmware's ELF in simavr on a pty.

The harness (``firmware/build/cdpr-sim``) prints its pty path first, like the
Python device. With byte or frame faults (``--faults corrupt=..,drop=..``) a
relay sits between the host's pty and the harness's, applying the same
:class:`FaultyChannel` as the Python device's server.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import os
import select
import shutil
import signal
import subprocess
import sys
import time
import tty
from pathlib import Path
from types import FrameType

from cdprhost.errors import InputError
from firmware_protocol.device.faults import FaultSpec, FaultyChannel

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware"
# CDPRHOST_STEP_ENGINE=1: the firmware built with the step engine (-DSTEP_ENGINE=1) into its
# own directory, firmware/build/engine, so that the default build is not disturbed (the
# tests and `cdprhost sim-device --firmware avr` then run that build)
STEP_ENGINE_ENV = "CDPRHOST_STEP_ENGINE"
STEP_ENGINE = os.environ.get(STEP_ENGINE_ENV, "") not in ("", "0")
BUILD_DIR = FIRMWARE_DIR / "build" / "engine" if STEP_ENGINE else FIRMWARE_DIR / "build"
BUILD_FLAGS = ["BUILD=build/engine", "EXTRA_CFLAGS=-DSTEP_ENGINE=1"] if STEP_ENGINE else []
ELF = BUILD_DIR / "cdpr-sim.elf"  # the simulator target (mailbox hooks)
BOARD_ELF = BUILD_DIR / "cdpr.elf"  # the board target, the one flashed
HARNESS = BUILD_DIR / "cdpr-sim"
# the Mega 2560's stock bootloader (Debian's arduino-core-avr), for `harness_command(bootloader=...)`
BOOTLOADER_HEX = Path(
    "/usr/share/arduino/hardware/arduino/avr/bootloaders/stk500v2/stk500boot_v2_mega2560.hex"
)
INSTALL_HINT = (
    "the AVR toolchain or simavr is missing: install it with "
    "`apt-get install -y gcc-avr avr-libc simavr libsimavr-dev libelf-dev pkg-config`"
)


# the harness's figures (lost interrupts, ISR cycles, step timing) go to this file on exit
STATS_ENV = "CDPR_SIM_STATS"


def toolchain_missing() -> str | None:
    """None when the firmware and its harness can be built here, else how to fix it."""
    if shutil.which("avr-gcc") is None or shutil.which("make") is None:
        return INSTALL_HINT
    headers = ("/usr/include/simavr/sim_avr.h", "/usr/include/libelf.h")
    if not all(Path(h).exists() for h in headers):
        return INSTALL_HINT
    return None


def build() -> None:
    """Build the ELF and the harness (make decides what is stale)."""
    missing = toolchain_missing()
    if missing:
        raise InputError(missing, source="--firmware avr")
    # one make at a time: two test workers (or a test and `sim-device`) starting on a fresh
    # tree would otherwise compile into the same objects at once
    BUILD_DIR.mkdir(parents=True, exist_ok=True)
    with open(BUILD_DIR / ".make.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run(
            ["make", "-s", "-C", str(FIRMWARE_DIR), *BUILD_FLAGS, "all", "sim"],
            check=False,
            capture_output=True,
            text=True,
        )
    if proc.returncode != 0:
        raise InputError(
            f"building the firmware failed (make -C {FIRMWARE_DIR} {' '.join(BUILD_FLAGS)} all sim):\n{proc.stderr[-2000:]}",
            source="--firmware avr",
        )


def harness_command(
    *,
    speedup: float = 1.0,
    record: str | None = None,
    stats: str | None = None,
    time_limit: float | None = None,
    heater_fail_after: float | None = None,
    exit_on_hangup: bool = False,
    bootloader: Path | None = None,
    thermistor_open_after: float | None = None,
    thermistor_short_after: float | None = None,
    hotend_start_c: float | None = None,
) -> list[str]:
    cmd = [str(HARNESS), str(ELF), "--speedup", f"{speedup:g}"]
    if record:
        cmd += ["--record", str(record)]
    if stats:
        cmd += ["--stats", str(stats)]
    if time_limit:
        cmd += ["--time-limit", f"{time_limit:g}"]
    if heater_fail_after is not None:
        cmd += ["--heater-fail-after", f"{heater_fail_after:g}"]
    if thermistor_open_after is not None:
        cmd += ["--thermistor-open-after", f"{thermistor_open_after:g}"]
    if thermistor_short_after is not None:
        cmd += ["--thermistor-short-after", f"{thermistor_short_after:g}"]
    if hotend_start_c is not None:
        cmd += ["--hotend-start-c", f"{hotend_start_c:g}"]
    if exit_on_hangup:
        cmd.append("--exit-on-hangup")
    if bootloader is not None:
        cmd += ["--bootloader", str(bootloader)]
    return cmd


class Relay:
    """Our own pty <-> the harness's pty, through a FaultyChannel each way."""

    def __init__(self, harness_pty: str, faults: FaultSpec):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.dev = os.open(harness_pty, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.dev)
        self.to_dev = FaultyChannel(faults, seed_offset=1)
        self.to_host = FaultyChannel(faults, seed_offset=2)
        # What a pty did not take yet, per destination: kept and written first next time
        # (a pty holds a few kB; a host or harness that reads late must not lose bytes).
        self.pending: dict[int, bytearray] = {self.dev: bytearray(), self.master: bytearray()}
        self.t0 = time.monotonic()

    def step(self, wait: float = 0.005) -> None:
        ready, _, _ = select.select([self.master, self.dev], [], [], wait)
        now = time.monotonic() - self.t0
        for fd, chan in ((self.master, self.to_dev), (self.dev, self.to_host)):
            if fd in ready:
                with contextlib.suppress(BlockingIOError, OSError):
                    chan.send(os.read(fd, 65536), now)
        for fd, chan in ((self.dev, self.to_dev), (self.master, self.to_host)):
            pending = self.pending[fd]
            pending += chan.receive(now)
            if pending:
                with contextlib.suppress(BlockingIOError, OSError):
                    del pending[: os.write(fd, pending)]

    def close(self) -> None:
        for fd in (self.master, self.slave, self.dev):
            with contextlib.suppress(OSError):
                os.close(fd)


def run(args: argparse.Namespace, faults: FaultSpec) -> int:
    """The CLI entry: build if needed, start the harness, print the pty, serve until SIGTERM."""
    if faults.reset_after or faults.stall_after:
        raise InputError(
            "reset_after and stall_after are not supported with --firmware avr", source="--faults"
        )
    if getattr(args, "truth", None):
        raise InputError("the virtual mocap needs --firmware python", source="--truth")
    build()
    proc = subprocess.Popen(
        harness_command(
            speedup=args.speedup,
            record=args.record,
            heater_fail_after=faults.heater_fail_after,
            thermistor_open_after=faults.thermistor_open_after,
            thermistor_short_after=faults.thermistor_short_after,
            hotend_start_c=faults.hotend_start_c,
            stats=os.environ.get(STATS_ENV),
        ),
        stdout=subprocess.PIPE,
        text=True,
    )
    path = proc.stdout.readline().strip() if proc.stdout else ""
    if not path.startswith("/dev/"):
        proc.wait()
        raise InputError("the simavr harness did not start", source="--firmware avr")
    stopping = False

    def stop(signum: int, frame: FrameType | None) -> None:
        nonlocal stopping
        stopping = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    # SIGUSR1: an external reset (the DTR auto-reset a pty cannot carry), as the Python device
    signal.signal(signal.SIGUSR1, lambda signum, frame: proc.send_signal(signal.SIGUSR1))
    lossy = faults.lossy or faults.latency_ms or faults.jitter_ms
    relay = Relay(path, faults) if lossy else None
    print(relay.path if relay else path, flush=True)
    print(
        f"cdprhost sim-device: AVR firmware {ELF.name} in simavr on {relay.path if relay else path} "
        f"(speedup {args.speedup:g}, faults: {args.faults or 'none'})",
        file=sys.stderr,
        flush=True,
    )
    try:
        while not stopping and proc.poll() is None:
            if relay:
                relay.step()
            else:
                time.sleep(0.05)
    finally:
        if relay:
            relay.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        code = proc.wait()
    return 0 if code == 0 else 1
