"""The device's record of executed move segments, and its JSON-lines file.

One entry per executed segment: ``{"seq": n, "steps": [n1, n2, n3, e], "t": s}``
where ``seq`` counts segments from 1 since the device booted, ``steps`` are the
absolute step positions after the segment, and ``t`` is the device's motion clock
(the sum of executed segment, dwell and homing durations) in seconds, so it depends
only on what was executed, never on link timing. Entries after a simulated reset
carry ``"boot": k`` (k >= 1); an aborted segment carries ``"error"``.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile


def record_entry(
    seq: int,
    steps: list[int],
    motion_ticks: int,
    clock_hz: int,
    boot: int = 0,
    error: str | None = None,
) -> dict:
    entry: dict = {"seq": seq, "steps": steps, "t": round(motion_ticks / clock_hz, 6)}
    if boot:
        entry["boot"] = boot
    if error:
        entry["error"] = error
    return entry


def write_record(path: str | os.PathLike[str], entries: list[dict]) -> None:
    """Write entries as JSON lines, atomically: the file is complete or absent, never half
    written (a temporary file beside it, renamed over it only on success)."""
    target = os.fspath(path)
    folder = os.path.dirname(target) or "."
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(target)}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            for e in entries:
                fh.write(json.dumps(e, separators=(",", ":")) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def read_record(path: str | os.PathLike[str]) -> list[dict]:
    with open(path, encoding="utf-8") as fh:
        return [json.loads(line) for line in fh if line.strip()]
