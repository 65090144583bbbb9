"""The exact (slow) path: one line parsed word by word, with columns, N numbers and checksums.

Used for lines the vectorised tokenizer does not take (checksums, parenthesised
comments, text arguments, flags without numbers, odd characters) and to find the
column of an error.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from cdprhost.gcode.errors import GcodeError, quoted

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)\Z")
_RUN = re.compile(r"[ \t]*([+\-0-9.]*)")
_CHECKSUM = re.compile(r"\*[ \t]*(\d+)[ \t\r]*(?:;.*)?\Z")
_SPACE = " \t\r\v\f"
_INF = float("inf")

# Commands whose argument is free text (the rest of the line).
TEXT_COMMANDS = frozenset({"M117", "M118", "M23", "M28", "M30", "M32", "M33", "M928", "M486"})
# A line starting with one of these letters continues the motion command (strict numbers).
MOTION_LETTERS = frozenset("XYZEFIJR")


@dataclass(slots=True)
class Word:
    """One ``letter value`` word; ``value`` None for a bare letter; ``column`` 1-based."""

    letter: str
    value: float | None
    column: int
    raw: str


@dataclass(slots=True)
class ParsedLine:
    """A parsed line: command word first (N word removed), then parameters."""

    words: list[Word] = field(default_factory=list)
    n: int | None = None
    text: str | None = None


def command_name(word: Word) -> str:
    """``G1``, ``M104``, ``M862.3``: the command a word names (value as written)."""
    return word.letter + word.raw[1:].strip()


def parse_line(
    text: str,
    line: int,
    path: str,
    *,
    strict_params: frozenset[str] = frozenset(),
    flag_commands: frozenset[str] = frozenset(),
) -> ParsedLine:
    """Parse ``text``; raise `GcodeError` with the column of the offending word.

    Parameters are checked strictly (bad numbers are errors) for commands in
    ``strict_params``; other commands keep what parses and ignore the rest. A bare
    letter glued to another letter (``Xabc``) is malformed unless the command is in
    ``flag_commands`` (``G28 XY``).
    """
    code = _verify_checksum(text, line, path)
    compact = not any(c in " \t" for c in code.split(";", 1)[0].strip())
    out = ParsedLine()
    i, n = 0, len(code)
    strict = True
    flags_ok = False
    command: str | None = None
    while i < n:
        ch = code[i]
        if ch in _SPACE:
            i += 1
            continue
        if ch == ";":
            break
        if ch == "(":
            close = code.find(")", i)
            if close < 0:
                raise GcodeError(path, line, i + 1, "unclosed '(' comment")
            i = close + 1
            continue
        if not ch.isascii() or not ch.isalpha():
            if strict:
                raise GcodeError(path, line, i + 1, f"unexpected character {quoted(ch)}")
            i += 1
            continue
        m = _RUN.match(code, i + 1)
        run = m.group(1) if m else ""
        end = m.end() if (m and run) else i + 1
        raw = code[i:end]
        letter = ch.upper()
        if letter == "E" and i > 0 and code[i - 1] in "0123456789." and run and not compact:
            glued = _word_text(code, _number_start(code, i))
            raise GcodeError(
                path,
                line,
                _number_start(code, i) + 1,
                f"number with an exponent {quoted(glued)}: write plain decimals "
                "(or a space before E, the extruder)",
            )
        value: float | None = None
        if run:
            if _NUMBER.match(run):
                value = float(run)
                if value in (_INF, -_INF):
                    if strict:
                        raise GcodeError(path, line, i + 1, f"number out of range {raw.strip()!r}")
                    value = None
            elif strict:
                raise GcodeError(
                    path,
                    line,
                    i + 1,
                    f"malformed number {quoted(_word_text(code, i))}" + _in(command),
                )
        if command is None and letter == "N" and out.n is None and not out.words:
            if value is None or value != int(value) or value < 0:
                raise GcodeError(
                    path, line, i + 1, f"malformed line number {quoted(_word_text(code, i))}"
                )
            out.n = int(value)
            i = end
            continue
        word = Word(letter, value, i + 1, raw)
        if command is None:
            if value is None:
                raise GcodeError(
                    path, line, i + 1, f"malformed command {quoted(_word_text(code, i))}"
                )
            command = letter + run.strip()
            word.raw = letter + run.strip()
            out.words.append(word)
            strict = command in strict_params or letter in MOTION_LETTERS
            flags_ok = command in flag_commands
            if command in TEXT_COMMANDS:
                out.text = code[end:].split(";", 1)[0].strip()
                return out
        else:
            if strict and not flags_ok and value is None and end < n and code[end].isalpha():
                raise GcodeError(
                    path,
                    line,
                    i + 1,
                    f"malformed number {quoted(_word_text(code, i))}" + _in(command),
                )
            out.words.append(word)
        i = end
    return out


def find_column(text: str, letter: str, occurrence: int = 0) -> int:
    """1-based column of the ``occurrence``-th word starting with ``letter`` (0 if absent)."""
    code = _strip_checksum(text)
    seen = 0
    i, n = 0, len(code)
    while i < n:
        ch = code[i]
        if ch == ";":
            break
        if ch == "(":
            close = code.find(")", i)
            i = n if close < 0 else close + 1
            continue
        if ch.isascii() and ch.isalpha() and ch.upper() == letter:
            if seen == occurrence:
                return i + 1
            seen += 1
        i += 1
    return 0


def word_at(text: str, column: int) -> str:
    """The whitespace-delimited word starting at 1-based ``column``."""
    return _word_text(text, column - 1)


def _number_start(code: str, i: int) -> int:
    """Index of the letter whose number ends just before index ``i``."""
    j = i
    while j > 0 and code[j - 1] in "0123456789.+-":
        j -= 1
    return max(j - 1, 0)


def _word_text(code: str, i: int) -> str:
    j = i + 1
    while j < len(code) and code[j] not in " \t\r;(*":
        j += 1
    return code[i:j]


def _in(command: str | None) -> str:
    return f" in {command}" if command else ""


def _strip_checksum(text: str) -> str:
    star = _checksum_star(text)
    return text if star < 0 else text[:star]


def _checksum_star(text: str) -> int:
    """Index of the checksum ``*`` (outside comments), or -1."""
    i = 0
    n = len(text)
    while i < n:
        ch = text[i]
        if ch == ";":
            return -1
        if ch == "(":
            close = text.find(")", i)
            if close < 0:
                return -1
            i = close + 1
            continue
        if ch == "*":
            return i
        i += 1
    return -1


def _verify_checksum(text: str, line: int, path: str) -> str:
    """Check ``*cs`` (XOR of all bytes before ``*``); return the text before it."""
    star = _checksum_star(text)
    if star < 0:
        return text
    m = _CHECKSUM.match(text, star)
    if m is None:
        raise GcodeError(
            path,
            line,
            star + 1,
            f"malformed checksum {quoted(text[star:].split(';', maxsplit=1)[0].strip())}",
        )
    expected = int(m.group(1))
    actual = 0
    for b in text[:star].encode("utf-8", "surrogateescape"):
        actual ^= b
    if actual != expected:
        raise GcodeError(
            path, line, star + 1, f"checksum mismatch: line says {expected}, computed {actual}"
        )
    return text[:star]
