"""`cdprhost sim-device` as its own process on a pseudo-terminal, driven through pyserial."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import serial

from cdprhost.link import DeviceReset, open_link
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.message_codec import decode_messages, encode_message
from firmware_protocol.messages import (
    Hello,
    Ident,
)
from firmware_protocol.segments import SegmentContext
from firmware_protocol.streams import demo_stream, expected_record

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


def start_device(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, str, Path]:
    record = tmp_path / "record.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdprhost", "sim-device", "--record", str(record), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    path = proc.stdout.readline().strip()
    assert path.startswith("/dev/"), proc.stderr.read()
    return proc, path, record


def stop_device(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()


def read_record(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.mark.timeout(60)
def test_stream_disconnect_reconnect_and_record(tmp_path):
    proc, path, record = start_device(tmp_path, "--speedup", "50")
    try:
        # raw pyserial first: HELLO by hand, IDENT back
        with serial.Serial(path, 250000, timeout=0.5, exclusive=True) as port:
            port.write(encode_frame(Kind.URGENT, 0, 0, encode_message(Hello(77))))
            d = Deframer()
            frames = []
            for _ in range(20):
                frames += [f for f in d.feed(port.read(256)) if f.kind == Kind.URGENT]
                if frames:
                    break
            idents = [
                m
                for f in frames
                for m in decode_messages(f.payload, SegmentContext())
                if isinstance(m, Ident)
            ]
            assert idents and idents[0].nonce == 77 and idents[0].firmware_name == "cdpr-sim"
        first = demo_stream(300, seed=1)
        link = open_link(path)
        assert link.queue_segments(first) == range(1, 301)
        link.wait_idle(20)
        link.close()
        second = demo_stream(50, seed=2)
        link = open_link(path)  # reconnect: numbering continues
        assert link.progress.segments_done == 300
        assert link.queue_segments(second) == range(301, 351)
        link.wait_idle(20)
        link.close()
    finally:
        assert stop_device(proc) == 0
    rec = read_record(record)
    exp = expected_record(first)
    exp += expected_record(
        second, start=exp[-1]["steps"], first_seq=301, start_ticks=round(exp[-1]["t"] * 100_000)
    )
    assert rec == exp


@pytest.mark.timeout(90)
def test_faulty_device_record_equals_clean_record(tmp_path):
    batch = demo_stream(800, seed=5)
    records = []
    for faults in (None, "corrupt=0.001,drop=0.001,dup=0.001,seed=4"):
        sub = tmp_path / ("clean" if faults is None else "faulty")
        sub.mkdir()
        proc, path, record = start_device(
            sub, "--speedup", "20", *(["--faults", faults] if faults else [])
        )
        try:
            link = open_link(path)
            link.queue_segments(batch)
            link.wait_idle(30)
            link.close()
        finally:
            assert stop_device(proc) == 0
        records.append(read_record(record))
    assert records[0] == records[1] == expected_record(batch)


@pytest.mark.timeout(60)
def test_reset_over_the_pty_names_the_last_segment(tmp_path):
    proc, path, record = start_device(tmp_path, "--speedup", "20", "--faults", "reset_after=400")
    try:
        link = open_link(path)
        with pytest.raises(DeviceReset) as exc:
            link.queue_segments(demo_stream(2000, seed=1))
            link.wait_idle(30)
        assert exc.value.last_segment == 400
        link.close()
    finally:
        assert stop_device(proc) == 0
    assert read_record(record)[-1]["seq"] == 400
