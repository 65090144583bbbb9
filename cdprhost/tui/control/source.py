"""Random access to the text of a G-code file by line number (1-based).

Built once per opened file: one pass over the bytes records where every line
starts, so the print screen can show the current line and jump to a violation
without rereading the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


class SourceLines:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._data = self.path.read_bytes()
        newlines = np.flatnonzero(np.frombuffer(self._data, dtype=np.uint8) == 0x0A)
        starts = np.concatenate(([0], newlines + 1))
        if starts[-1] >= len(self._data):  # file ends with a newline: no empty last line
            starts = starts[:-1]
        self._starts = starts.astype(np.int64)

    def __len__(self) -> int:
        return int(self._starts.size)

    def line(self, number: int) -> str:
        """The text of line ``number`` (1-based) without its end of line; "" outside the file."""
        i = number - 1
        if not 0 <= i < len(self):
            return ""
        end = int(self._starts[i + 1]) if i + 1 < len(self) else len(self._data)
        return self._data[int(self._starts[i]) : end].decode("utf-8", "replace").rstrip("\r\n")

    def around(self, number: int, before: int = 3, after: int = 3) -> list[tuple[int, str]]:
        """(line number, text) for the lines around ``number`` that exist."""
        lo, hi = max(1, number - before), min(len(self), number + after)
        return [(n, self.line(n)) for n in range(lo, hi + 1)]
