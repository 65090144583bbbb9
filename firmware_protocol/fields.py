"""Wire field types of the message table: their ranges and the :class:`Field` record."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

MAX_TEXT = 32  # bytes of a text field

# value ranges of each wire type
TYPE_RANGE: dict[str, tuple[int, int]] = {
    "u8": (0, 0xFF),
    "u16": (0, 0xFFFF),
    "u32": (0, 0xFFFF_FFFF),
    "i16": (-0x8000, 0x7FFF),
    "i32": (-0x8000_0000, 0x7FFF_FFFF),
}
_BITS = {"u16": 16, "u32": 32, "i16": 16, "i32": 32}


class MessageError(ValueError):
    """A payload that does not parse (unknown opcode, truncated or out-of-range field).

    ``offset`` is the payload byte where the offending message starts; ``opcode`` its opcode."""

    def __init__(self, text: str, *, offset: int = 0, opcode: int = 0):
        super().__init__(text)
        self.offset = offset
        self.opcode = opcode


@dataclass(frozen=True)
class Field:
    """One field of the table.

    ``type``: u8, u16, u32, i16, i32 or text. ``count`` > 1: a fixed array; with ``mask``
    only the entries whose bit is set in the named earlier field are on the wire; with
    ``counted`` a u8 count (0..count) precedes the entries. ``lo``/``hi``: the value
    range the protocol fixes (within the type's own range), checked by every decoder;
    ``limit``: a further bound that depends on the device (named by the ``Ident`` field
    that announces it), checked by the device when it executes the command.
    """

    name: str
    type: str
    count: int = 1
    mask: str | None = None
    counted: bool = False
    lo: int | None = None
    hi: int | None = None
    limit: str = ""
    doc: str = ""

    @property
    def range(self) -> tuple[int, int]:
        """The statically known range (type range narrowed by lo/hi when numeric)."""
        lo, hi = TYPE_RANGE.get(self.type, (0, MAX_TEXT))
        if self.lo is not None:
            lo = max(lo, self.lo)
        if self.hi is not None:
            hi = min(hi, self.hi)
        return lo, hi


def F(name: str, type_: str, doc: str = "", **kw: Any) -> Field:
    return Field(name, type_, doc=doc, **kw)
