"""`GcodeError`: bad G-code input, named by file, line and column."""

from __future__ import annotations

from cdprhost.errors import InputError


def printable(text: str) -> str:
    """``text`` for a message: undecodable bytes (kept as surrogates) and control
    characters as ``\\xNN`` escapes, everything else as written."""
    raw = text.encode("utf-8", "surrogateescape")
    out = raw.decode("utf-8", "backslashreplace")
    if out.isprintable():
        return out
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in out)


def quoted(text: str) -> str:
    """``'text'`` for a message (see `printable`)."""
    return f"'{printable(text)}'"


class GcodeError(InputError):
    """Malformed or unsupported G-code. ``line`` and ``column`` are 1-based (column 0: the
    whole line; line 0: the whole file)."""

    def __init__(self, path: str, line: int, column: int, reason: str):
        self.path = path
        self.line = line
        self.column = column
        self.reason = reason
        if line <= 0:
            where = path
        elif column > 0:
            where = f"{path}:{line}:{column}"
        else:
            where = f"{path}:{line}"
        super().__init__(f"{where}: {reason}")
        self.source = path
