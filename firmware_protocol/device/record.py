"""The device's record of executed move segments, and its JSON-lines file.

One entry per executed segment: ``{"seq": n, "steps": [n1, n2, n3, e], "t": s}``
where ``seq`` counts segments from 1 since the device booted, ``steps`` are the
absolute step positions after the segment, and ``t`` is the device's motion clock
(the sum of executed segment, dwell and homing durations) in seconds, so it depends
only on what was executed, never on link timing. Entries after a simulated reset
carry ``"boot": k`` (k >= 1); an aborted segment carries ``"error"``.

:class:`SegmentRecord` keeps the entries in compact integer columns (no Python
object per segment, so a long print never makes the garbage collector pause the
device) and, given a path, streams each entry to its file as it executes (so a
killed simulator still leaves everything up to its last buffered line). Reading an
entry builds its dict on demand.

With ``keep`` n, only the newest entries stay in memory: at most ``n + n // 8`` (the
oldest are dropped in batches, so appending stays cheap); :attr:`SegmentRecord.dropped`
counts them and the file, if any, still gets every entry. A device that runs for weeks
(the terminal UI's embedded one) keeps a bounded record this way; indices and ``len``
cover the entries held.
"""

from __future__ import annotations

import json
import os
from array import array
from collections.abc import Iterator, Sequence
from typing import IO, Any, overload

import numpy as np


def record_entry(
    seq: int,
    steps: Sequence[int],
    motion_ticks: int,
    clock_hz: int,
    boot: int = 0,
    error: str | None = None,
) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "seq": seq,
        "steps": [int(v) for v in steps],
        "t": round(motion_ticks / clock_hz, 6),
    }
    if boot:
        entry["boot"] = boot
    if error:
        entry["error"] = error
    return entry


def _line(entry: dict[str, Any]) -> str:
    return json.dumps(entry, separators=(",", ":")) + "\n"


class SegmentRecord(Sequence[dict[str, Any]]):
    """Executed segments in columns; optionally streamed to ``path`` (JSON lines)."""

    def __init__(
        self,
        path: str | os.PathLike[str] | None = None,
        *,
        clock_hz: int = 100_000,
        keep: int | None = None,
    ):
        if keep is not None and keep < 1:
            raise ValueError(f"keep must be at least 1, not {keep}")
        self.clock_hz = clock_hz
        self.keep = keep
        self.dropped = 0  # the oldest entries no longer held (``keep``)
        self._seq = array("q")
        self._steps = array("q")  # 4 per entry
        self._ticks = array("q")
        self._boot = array("q")
        self._error = array("q")  # index into ERROR_NAMES
        self._errors: list[str] = [""]
        self._fh: IO[str] | None = None
        self.path = os.fspath(path) if path is not None else None
        if self.path is not None:
            self._fh = open(self.path, "w", encoding="utf-8", buffering=1 << 16)  # noqa: SIM115 - held for the device's life, closed by close()

    def append(
        self,
        seq: int,
        steps: Sequence[int],
        motion_ticks: int,
        boot: int = 0,
        error: str | None = None,
    ) -> None:
        code = 0
        if error:
            if error not in self._errors:
                self._errors.append(error)
            code = self._errors.index(error)
        self._seq.append(seq)
        self._steps.extend(steps)
        self._ticks.append(motion_ticks)
        self._boot.append(boot)
        self._error.append(code)
        if self._fh is not None:
            self._fh.write(
                _line(record_entry(seq, steps, motion_ticks, self.clock_hz, boot, error))
            )
        if self.keep is not None and len(self._seq) > self.keep + self.keep // 8:
            self._drop(len(self._seq) - self.keep)

    def _drop(self, n: int) -> None:
        """Forget the ``n`` oldest entries (the file keeps them)."""
        for column in (self._seq, self._ticks, self._boot, self._error):
            del column[:n]
        del self._steps[: 4 * n]
        self.dropped += n

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    # ------------------------------------------------------------------ reading

    def __len__(self) -> int:
        return len(self._seq)

    def _entry(self, i: int) -> dict[str, Any]:
        k = 4 * i
        return record_entry(
            self._seq[i],
            self._steps[k : k + 4],
            self._ticks[i],
            self.clock_hz,
            self._boot[i],
            self._errors[self._error[i]] or None,
        )

    @overload
    def __getitem__(self, index: int) -> dict[str, Any]: ...

    @overload
    def __getitem__(self, index: slice) -> list[dict[str, Any]]: ...

    def __getitem__(self, index: int | slice) -> dict[str, Any] | list[dict[str, Any]]:
        if isinstance(index, slice):
            return [self._entry(i) for i in range(*index.indices(len(self)))]
        n = len(self)
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError("record index out of range")
        return self._entry(index)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return (self._entry(i) for i in range(len(self)))

    def __eq__(self, other: object) -> bool:
        if isinstance(other, SegmentRecord):
            other = list(other)
        if not isinstance(other, list):
            return NotImplemented
        return len(other) == len(self) and all(a == b for a, b in zip(self, other))

    __hash__ = None  # type: ignore[assignment]

    def steps(self, last: int | None = None) -> np.ndarray:
        """(n, 4) absolute steps after each executed segment (the last ``last`` ones)."""
        arr = np.frombuffer(self._steps, dtype=np.int64).reshape(-1, 4) if len(self) else None
        if arr is None:
            return np.zeros((0, 4), dtype=np.int64)
        return (arr if last is None else arr[-last:]).copy()

    def __repr__(self) -> str:
        return f"SegmentRecord({len(self)} segments{', ' + self.path if self.path else ''})"


def read_record(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    with open(path, encoding="utf-8") as fh:
        return [json.loads(line) for line in fh if line.strip()]
