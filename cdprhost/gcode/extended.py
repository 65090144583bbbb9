"""Extended commands (Klipper's ``NAME KEY=value ...``, OctoPrint's ``@pause``).

A line whose first word is not a letter and a number (``PRINT_START BED=60``,
``EXCLUDE_OBJECT_START NAME=part_1``, ``GET_POSITION``, ``@pause``) is an extended
command. They are found per block before tokenising and their lines blanked, so
the vectorised tokenizer never sees them; each becomes an `Other` with its
``KEY=value`` parameters (keys upper-case, values as written, quotes removed).
"""

from __future__ import annotations

import re

from cdprhost.gcode.classify import Other

# first word: '@...', anything with '_', or two letters in a row (not G1, M104, T0)
_LINE = re.compile(
    rb"(?m)^[ \t]*(?:[Nn][0-9]+[ \t]+)?(@\w*|[A-Za-z]*_\w*|[A-Za-z]{2}\w*)(?=[ \t\r]|$)([^\n]*)"
)
_PARAM = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)=("[^"]*"|\S*)')


def extract(code: bytes) -> tuple[list[Other], bytes]:
    """Extended commands of a comment-free block and the block with their lines blanked."""
    if not _LINE.search(code):
        return [], code
    found: list[Other] = []
    buf = bytearray(code)
    line = 0
    pos = 0
    for m in _LINE.finditer(code):
        start = m.start()
        line += code.count(b"\n", pos, start)
        pos = start
        word = m.group(1).decode("ascii").upper()
        rest = m.group(2).decode("utf-8", "surrogateescape").strip()
        params = {k.upper(): v.strip('"') for k, v in _PARAM.findall(rest)}
        found.append(Other(line, word, {}, rest, params))
        buf[start : m.end()] = b" " * (m.end() - start)
    return found, bytes(buf)
