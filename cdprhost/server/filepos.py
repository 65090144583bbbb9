"""OctoPrint's ``progress.filepos``: the byte offset where the job's current G-code line starts.

The job says which line the device executes (:attr:`~cdprhost.job.state.JobSnapshot.line`);
the byte offset of that line is found from a sparse index: the offset of every
:data:`STRIDE`-th line, built once per file by one streamed pass in blocks (never the whole
file in memory), and the remaining lines counted forward from the nearest mark. A 100 MB
file of 4 million lines keeps about 1,000 marks (8 kB); a poll reads at most one stride of
lines (tens of kB), however often phone apps and slicers ask.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

STRIDE = 4096  # lines between two marks
BLOCK = 1 << 20  # bytes read at a time


@dataclass(frozen=True)
class LineMarks:
    key: tuple[str, int, int]  # (path, mtime_ns, size): the file the marks describe
    starts: np.ndarray  # int64: byte offset of lines 1, 1 + stride, 1 + 2 * stride, ...
    lines: int  # lines in the file (a last line without a newline counts)
    stride: int = STRIDE


def _key(path: Path) -> tuple[str, int, int]:
    st = path.stat()
    return (str(path), st.st_mtime_ns, st.st_size)


def build_marks(path: Path, stride: int = STRIDE, block: int = BLOCK) -> LineMarks:
    """Blocking: one streamed pass over ``path``."""
    key = _key(path)
    marks: list[np.ndarray] = [np.zeros(1, dtype=np.int64)]
    newlines = 0  # newlines seen so far: line n + 1 starts after the n-th
    offset = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(block):
            at = np.flatnonzero(np.frombuffer(chunk, dtype=np.uint8) == 10)
            # line k starts after newline k - 1; marks at lines 1 + j * stride, j >= 1
            numbers = newlines + 1 + np.arange(at.size)  # the newline's ordinal (1-based)
            keep = numbers % stride == 0
            if keep.any():
                marks.append((offset + at[keep] + 1).astype(np.int64))
            newlines += int(at.size)
            offset += len(chunk)
    lines = newlines + (1 if offset and not _ends_with_newline(path, offset) else 0)
    return LineMarks(key, np.concatenate(marks), max(lines, 1), stride)


def _ends_with_newline(path: Path, size: int) -> bool:
    with open(path, "rb") as fh:
        fh.seek(size - 1)
        return fh.read(1) == b"\n"


def offset_of(path: Path, marks: LineMarks, line: int, block: int = 1 << 16) -> int:
    """Blocking: the byte offset where ``line`` (1-based, clamped to the file) starts."""
    line = min(max(line, 1), marks.lines)
    j = min((line - 1) // marks.stride, marks.starts.size - 1)
    pos = int(marks.starts[j])
    todo = line - 1 - j * marks.stride  # newlines to pass from the mark
    if todo == 0:
        return pos
    with open(path, "rb") as fh:
        fh.seek(pos)
        while chunk := fh.read(block):
            at = np.flatnonzero(np.frombuffer(chunk, dtype=np.uint8) == 10)
            if at.size >= todo:
                return pos + int(at[todo - 1]) + 1
            todo -= int(at.size)
            pos += len(chunk)
    return pos


class FilePosition:
    """The marks of the last file asked about (one print at a time), rebuilt when it changes."""

    def __init__(self) -> None:
        self._marks: LineMarks | None = None
        self._lock = threading.Lock()

    def __call__(self, path: Path | None, line: int) -> int | None:
        """Blocking (one pass the first time per file): the offset of ``line``, or None."""
        if path is None or line < 1:
            return None
        try:
            with self._lock:
                key = _key(path)
                if self._marks is None or self._marks.key != key:
                    self._marks = build_marks(path)
                marks = self._marks
            return offset_of(path, marks, line)
        except OSError:
            return None
