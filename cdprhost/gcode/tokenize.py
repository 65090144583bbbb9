"""Vectorised tokenizer: a block of comment-free G-code bytes -> (line, letter, value) arrays.

Lines in the common form (every letter directly followed by its number) are
tokenised with numpy. Numbers are read as integers with the dot removed
(``np.fromstring``) and scaled by a power of ten: exact, and equal to ``float()``
for up to 15 digits. Any line with something unusual (other characters, a letter
without a number, a malformed or very long number, an N word, an E glued to the
number before it) is returned as *slow*, for the exact per-line parser.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPACE, LETTER, DIGIT, DOT, SIGN, NEWLINE, JUNK = range(7)
MAX_NUMBER_CHARS = 15  # longer numbers go to the exact path (int64/float64 exactness)

_CLASS = np.full(256, JUNK, dtype=np.uint8)
_CLASS[[ord(c) for c in " \t\r\v\f"]] = SPACE
_CLASS[ord("A") : ord("Z") + 1] = LETTER
_CLASS[ord("a") : ord("z") + 1] = LETTER
_CLASS[ord("0") : ord("9") + 1] = DIGIT
_CLASS[ord(".")] = DOT
_CLASS[[ord("+"), ord("-")]] = SIGN
_CLASS[ord("\n")] = NEWLINE

_LETTERS_TO_SPACE = bytes(32 if (65 <= i <= 90 or 97 <= i <= 122) else i for i in range(256))
_POW10 = 10.0 ** np.arange(MAX_NUMBER_CHARS + 1)


@dataclass(frozen=True, slots=True)
class Tokens:
    """Words of the fast lines, in order. ``line`` is the 0-based line index in the block.

    ``letter`` is the upper-case ASCII code. ``slow`` lists (sorted) the lines left out.
    """

    line: np.ndarray  # int64
    letter: np.ndarray  # uint8
    value: np.ndarray  # float64
    n_lines: int
    slow: np.ndarray  # int64


def tokenize(code: bytes) -> Tokens:
    """Tokenise ``code`` (ends with a newline; comments already removed)."""
    arr = np.frombuffer(code, dtype=np.uint8)
    cls = np.take(_CLASS, arr)
    nl_mask = cls == NEWLINE
    line_of = np.cumsum(nl_mask, dtype=np.int32)
    n_lines = int(line_of[-1]) if arr.size else 0
    letters = np.flatnonzero(cls == LETTER)
    numchar = (cls - np.uint8(DIGIT)) <= np.uint8(SIGN - DIGIT)
    run_start, run_end = _runs(numchar, cls, letters)
    dot_mask = cls == DOT
    dots = np.flatnonzero(dot_mask)
    if dots.size:
        dot_count = np.cumsum(dot_mask, dtype=np.int32)
        n_dots = dot_count[run_end - 1] - dot_count[run_start] + dot_mask[run_start]
    else:
        n_dots = np.zeros(run_start.size, dtype=np.int32)

    bad = _anomalies(arr, cls, letters, run_start, run_end, n_dots)
    slow = np.unique(line_of[bad]).astype(np.int64) if bad.size else np.empty(0, dtype=np.int64)
    if slow.size:
        letters = letters[_keep(line_of[letters], slow)]
        keep_run = _keep(line_of[run_start], slow)
        run_start, run_end, n_dots = run_start[keep_run], run_end[keep_run], n_dots[keep_run]
        dots = dots[_keep(line_of[dots], slow)]
        code = _blank_lines(code, np.flatnonzero(nl_mask), slow)
    values = _numbers(code, run_end, n_dots, dots)
    if values.size != letters.size:  # cannot happen after _anomalies; stay correct anyway
        every = np.unique(line_of[np.flatnonzero(cls == LETTER)]).astype(np.int64)
        return Tokens(_EMPTY_I, _EMPTY_U8, _EMPTY_F, n_lines, np.union1d(slow, every))
    return Tokens(
        line_of[letters].astype(np.int64), arr[letters] & np.uint8(0xDF), values, n_lines, slow
    )


_EMPTY_I = np.empty(0, dtype=np.int64)
_EMPTY_U8 = np.empty(0, dtype=np.uint8)
_EMPTY_F = np.empty(0, dtype=np.float64)


def _runs(
    numchar: np.ndarray, cls: np.ndarray, letters: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) of every maximal run of number characters."""
    run_end = np.flatnonzero(numchar[:-1] > numchar[1:]) + 1
    lead = numchar[letters + 1]
    if run_end.size == np.count_nonzero(lead):  # every run follows a letter (the usual case)
        return letters[lead] + 1, run_end
    run_start = np.flatnonzero(numchar[1:] > numchar[:-1]) + 1
    if numchar[0]:
        run_start = np.concatenate([[0], run_start])
    return run_start, run_end


def _keep(lines: np.ndarray, slow: np.ndarray) -> np.ndarray:
    idx = np.searchsorted(slow, lines)
    return slow[np.minimum(idx, slow.size - 1)] != lines


def _anomalies(
    arr: np.ndarray,
    cls: np.ndarray,
    letters: np.ndarray,
    run_start: np.ndarray,
    run_end: np.ndarray,
    n_dots: np.ndarray,
) -> np.ndarray:
    """Byte positions that make their line unsuitable for the fast path."""
    parts = [np.flatnonzero(cls == JUNK) if cls.max(initial=0) == JUNK else _EMPTY_I]
    after = cls[letters + 1]
    parts.append(letters[(after < DIGIT) | (after > SIGN)])  # letter without a number
    lower = arr[letters] | np.uint8(0x20)
    parts.append(letters[lower == ord("n")])  # N words: exact path
    glued_e = letters[(lower == ord("e")) & (letters > 0)]  # X1e5: an exponent, or a compact E
    prev = cls[glued_e - 1]
    parts.append(glued_e[(prev == DIGIT) | (prev == DOT)])
    if run_start.size:
        parts.append(run_start[cls[run_start - 1] != LETTER])  # number without a letter
        signs = np.flatnonzero(cls == SIGN)
        parts.append(signs[cls[signs - 1] != LETTER])  # sign not leading its number
        parts.append(run_start[n_dots > 1])
        length = run_end - run_start
        parts.append(run_start[length > MAX_NUMBER_CHARS])
        first = cls[run_start]
        second = cls[np.minimum(run_start + 1, arr.size - 1)]
        digit = (first == DIGIT) | ((length >= 2) & (second == DIGIT)) | (length >= 3)
        parts.append(run_start[~digit])
    return np.concatenate(parts)


def _blank_lines(code: bytes, newlines: np.ndarray, lines: np.ndarray) -> bytes:
    buf = bytearray(code)
    starts = np.where(lines > 0, newlines[np.maximum(lines - 1, 0)] + 1, 0)
    for s, e in zip(starts.tolist(), newlines[lines].tolist()):
        buf[s:e] = b" " * (e - s)
    return bytes(buf)


def _numbers(code: bytes, run_end: np.ndarray, n_dots: np.ndarray, dots: np.ndarray) -> np.ndarray:
    """Values of the (valid) number runs: digits as an integer, divided by 10**decimals."""
    if run_end.size == 0:
        return _EMPTY_F
    text = code.translate(_LETTERS_TO_SPACE, b".")
    mantissa = np.fromstring(text, dtype=np.int64, sep=" ")
    if mantissa.size != run_end.size:
        return _EMPTY_F
    decimals = np.zeros(run_end.size, dtype=np.int64)
    with_dot = n_dots == 1
    decimals[with_dot] = run_end[with_dot] - dots - 1
    return mantissa / _POW10[decimals]
