"""`GcodeError`: bad G-code input, named by file, line and column."""

from __future__ import annotations

from cdprhost.errors import InputError


class GcodeError(InputError):
    """Malformed or unsupported G-code. ``line`` and ``column`` are 1-based (column 0: whole line)."""

    def __init__(self, path: str, line: int, column: int, reason: str):
        self.path = path
        self.line = line
        self.column = column
        self.reason = reason
        where = f"{path}:{line}:{column}" if column > 0 else f"{path}:{line}"
        super().__init__(f"{where}: {reason}")
        self.source = path
