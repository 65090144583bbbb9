"""Start a simulated device (Python model or AVR firmware in simavr) and talk to it raw."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import serial

from cdprhost.sim import avr_device
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import Kind, encode_frame
from firmware_protocol.message_codec import decode_messages, encode_message, encode_messages
from firmware_protocol.messages import (
    GetStatus,
    Hello,
    Ident,
    Message,
    Ring,
    Status,
)
from firmware_protocol.segments import SegmentContext


@dataclass
class Device:
    kind: str
    proc: subprocess.Popen
    path: str
    record: Path
    stats_path: Path  # the AVR harness's figures, written when it exits

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(30)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()

    def stats(self) -> dict:
        """The harness's figures (AVR only; after stop)."""
        return json.loads(self.stats_path.read_text()) if self.stats_path.exists() else {}


def start(kind: str, tmp: Path, *args: str) -> Device:
    record = tmp / f"{kind}-record.jsonl"
    stats = tmp / f"{kind}-{time.monotonic_ns()}-stats.json"
    cmd = [sys.executable, "-m", "cdprhost", "sim-device", "--record", str(record)]
    cmd += ["--firmware", kind]
    env = dict(os.environ, **{avr_device.STATS_ENV: str(stats)})
    proc = subprocess.Popen(
        [*cmd, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    path = proc.stdout.readline().strip()
    if not path.startswith("/dev/"):
        proc.wait(10)
        raise RuntimeError(f"sim-device did not start: {proc.stderr.read()}")
    return Device(kind, proc, path, record, stats)


@dataclass
class RawHost:
    """A minimal host: HELLO by hand, then sequenced DATA through an Endpoint."""

    path: str
    port: serial.Serial = field(init=False)
    ep: Endpoint = field(init=False)
    ctx: SegmentContext = field(default_factory=SegmentContext)
    reports: list = field(default_factory=list)
    urgent: list = field(default_factory=list)
    flows: list = field(default_factory=list)
    rings: list = field(default_factory=list)  # RING after FLOW (3.2, a device with a ring)
    keepalive: float = 0.5  # GET_STATUS when nothing was sent for this long (0: never)
    _sent_at: float = 0.0
    _open: bool = False

    def __post_init__(self):
        self.port = serial.Serial(self.path, 250000, timeout=0)
        self.ep = Endpoint(window=8, rto_initial=0.25, rto_floor=0.01, rto_ceiling=1.0)
        self.t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self.t0

    def close(self) -> None:
        self.port.close()

    def write_raw(self, data: bytes) -> None:
        self.port.write(data)

    def pump(self, seconds: float = 0.02) -> None:
        end = time.monotonic() + seconds
        while True:
            data = self.port.read(4096)
            now = self.now()
            for inc in self.ep.feed(data, now) if data else []:
                msgs = decode_messages(inc.payload, SegmentContext())
                if inc.kind == "flow":
                    self.rings += [m for m in msgs if isinstance(m, Ring)]
                    msgs = [m for m in msgs if not isinstance(m, Ring)]
                {"data": self.reports, "urgent": self.urgent, "flow": self.flows}[inc.kind].extend(
                    msgs
                )
            if self.keepalive and self._open and now - self._sent_at > self.keepalive:
                self.ep.send(encode_messages([GetStatus()], self.ctx))
                self._sent_at = now
            for frame in self.ep.flush(now):
                self.port.write(frame)
            if time.monotonic() >= end:
                return
            time.sleep(0.002)

    def wait_for(self, pred, timeout: float = 10.0, what: str = "condition"):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.pump(0.02)
            hit = pred()
            if hit:
                return hit
        raise AssertionError(f"{what} did not happen within {timeout} s")

    def hello(self, nonce: int = 0x1234, timeout: float = 5.0, minor: int | None = None) -> Ident:
        hello = Hello(nonce) if minor is None else Hello(nonce, minor=minor)
        frame = encode_frame(Kind.URGENT, 0, 0, encode_message(hello))
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.port.write(frame)
            self.ep.reset_session()
            self.ctx = SegmentContext()
            t = time.monotonic() + 0.25
            while time.monotonic() < t:
                self.pump(0.02)
                for m in self.urgent:
                    if isinstance(m, Ident) and m.nonce == nonce:
                        self._open = True
                        self.ep.window_bytes = m.rx_window  # what the device can buffer
                        return m
        raise AssertionError("no IDENT")

    def urgent_send(self, msg: Message) -> None:
        self.write_raw(encode_frame(Kind.URGENT, 0, 0, encode_message(msg)))

    def send(self, *msgs: Message) -> None:
        self._sent_at = self.now()
        payload = encode_messages(list(msgs), self.ctx)
        self.ep.send(payload, items=sum(1 for m in msgs if m.QUEUED))
        self.pump(0.01)

    def status(self) -> Status:
        """A STATUS answered after everything received so far (keep-alive replies dropped)."""
        self.reports[:] = [m for m in self.reports if not isinstance(m, Status)]
        self.send(GetStatus())
        return self.wait_for(lambda: self.of(Status), what="STATUS")

    def of(self, cls, **fields):
        for m in self.reports:
            if isinstance(m, cls) and all(getattr(m, k) == v for k, v in fields.items()):
                return m
        return None
