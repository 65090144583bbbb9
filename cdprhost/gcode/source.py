"""Split a G-code source (file path or iterable of lines) into blocks of whole lines.

A block is ``bytes`` ending in ``b"\\n"``; memory is bounded by the block size, never
by the file size. Line ends are universal: LF, CRLF and a lone CR (old Mac files)
each end a line.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import islice
from typing import AnyStr

from cdprhost.errors import InputError
from cdprhost.gcode.errors import GcodeError

BLOCK_BYTES = 1 << 20
BLOCK_LINES = 32768
_BOM = b"\xef\xbb\xbf"


@dataclass(frozen=True, slots=True)
class Block:
    """``data``: whole lines ending in newline; ``first_line``: 1-based number of its first line."""

    data: bytes
    first_line: int


def source_name(
    source: str | os.PathLike[str] | Iterable[str | bytes], name: str | None = None
) -> str:
    """How errors name the source: ``name`` if given, else the path as written, else ``<lines>``."""
    if name is not None:
        return name
    if isinstance(source, (str, os.PathLike)):
        return os.fspath(source)
    return "<lines>"


def iter_blocks(
    source: str | os.PathLike[str] | Iterable[str | bytes],
    name: str,
    *,
    block_bytes: int = BLOCK_BYTES,
    block_lines: int = BLOCK_LINES,
) -> Iterator[Block]:
    """Blocks of a file (read ``block_bytes`` at a time) or of an iterable of lines."""
    if isinstance(source, (str, os.PathLike)):
        yield from _file_blocks(source, name, block_bytes)
    else:
        yield from _line_blocks(source, block_lines)


def _file_blocks(path: str | os.PathLike[str], name: str, block_bytes: int) -> Iterator[Block]:
    try:
        fh = open(path, "rb")  # noqa: SIM115 - closed by the with below; open errors named first
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=name) from None
    first_line = 1
    with fh:
        tail = b""
        first = True
        while True:
            data = fh.read(block_bytes)
            if first:
                data = data.removeprefix(_BOM)
                first = False
            if not data:
                break
            data = tail + data if tail else data
            if b"\r" in data:
                data, held = _universal(data)
            else:
                held = b""
            cut = data.rfind(b"\n") + 1
            if cut == 0:
                if len(data) > 4 * block_bytes:
                    raise GcodeError(
                        name,
                        first_line,
                        0,
                        f"line longer than {4 * block_bytes} bytes (no newline)",
                    )
                tail = data + held
                continue
            tail = data[cut:] + held
            block = data[:cut] if tail else data
            yield Block(block, first_line)
            first_line += block.count(b"\n")
        if tail:
            tail = tail.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
            yield Block(tail if tail.endswith(b"\n") else tail + b"\n", first_line)


def _universal(data: bytes) -> tuple[bytes, bytes]:
    """``data`` with CRLF and lone CR as LF; a final CR is held back (its LF may follow)."""
    held = b""
    if data.endswith(b"\r"):
        data, held = data[:-1], b"\r"
    return data.replace(b"\r\n", b"\n").replace(b"\r", b"\n"), held


def _line_blocks(lines: Iterable[str | bytes], block_lines: int) -> Iterator[Block]:
    first_line = 1
    it = iter(lines)
    while True:
        batch = list(islice(it, block_lines))
        if not batch:
            return
        data = _join(batch)
        yield Block(data, first_line)
        first_line += data.count(b"\n")


def _join(batch: list[str | bytes]) -> bytes:
    """The lines as one newline-terminated block (one encode for the common cases)."""
    kinds = {type(x) for x in batch}
    if kinds == {str}:
        fast = _join_same([x for x in batch if isinstance(x, str)], "\n", "\r")
        if fast is not None:
            return _encode(fast)
    elif kinds == {bytes}:
        fast_b = _join_same([x for x in batch if isinstance(x, bytes)], b"\n", b"\r")
        if fast_b is not None:
            return fast_b
    out = []
    for raw in batch:
        raw = _encode(raw).removesuffix(b"\n").removesuffix(b"\r")
        if b"\r" in raw:  # a lone CR ends a line too (a CR-only file read as one line)
            raw = _universal(raw)[0]
        elif b"\n" in raw:
            raise ValueError(
                "a line passed to the G-code reader contains a newline; split the text into lines"
            )
        out.append(raw)
    return b"\n".join(out) + b"\n"


def _join_same(batch: list[AnyStr], nl: AnyStr, cr: AnyStr) -> AnyStr | None:
    """Lines of one type joined when none has a CR inside (None: take the careful path)."""
    joined = nl.join(batch)
    if cr in joined:
        return None
    if joined.count(nl) == len(batch) - 1:  # no line carries a newline
        return joined + nl
    joined = nl[:0].join(batch)
    if joined.count(nl) == len(batch) and all(x.endswith(nl) for x in batch):
        return joined  # every line ends with one
    return None


def _encode(text: str | bytes) -> bytes:
    return text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text
