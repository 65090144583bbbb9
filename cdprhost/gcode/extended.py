"""Extended commands (Klipper's ``NAME KEY=value ...``, OctoPrint's ``@pause``).

A line whose first word is not a letter and a number (``PRINT_START BED=60``,
``EXCLUDE_OBJECT_START NAME=part_1``, ``GET_POSITION``, ``@pause``) is an extended
command; it becomes an `Other` with its ``KEY=value`` parameters (keys upper-case,
values as written, quotes removed).
"""

from __future__ import annotations

import re

from cdprhost.gcode.classify import Other

# first word: '@...', anything with '_', or two letters in a row (not G1, M104, T0)
_LINE = re.compile(
    r"[ \t]*(?:[Nn][0-9]+[ \t]+)?(@\w*|[A-Za-z]*_\w*|[A-Za-z]{2}\w*)(?=[ \t\r]|$)(.*)"
)
_PARAM = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)=("[^"]*"|\S*)')


def parse(text: str, index: int) -> Other | None:
    """The extended command on line ``text`` (block line ``index``), or None.

    Such lines never take the tokenizer's fast path (``_`` and ``@`` are not G-code
    characters; a letter followed by a letter has no number), so only the few slow
    lines are looked at.
    """
    code = text.split(";", 1)[0].rstrip()
    m = _LINE.match(code)
    if m is None:
        return None
    word = m.group(1).upper()
    rest = m.group(2).strip()
    params = {k.upper(): v.strip('"') for k, v in _PARAM.findall(rest)}
    return Other(index, word, {}, rest, params)
