"""Compact integers: unsigned LEB128 varints and zigzag for signed values.

A varint stores 7 bits per byte, least significant group first; the top bit of a
byte is set when another byte follows. Zigzag maps 0, -1, 1, -2, ... to
0, 1, 2, 3, ... so small magnitudes of either sign take one byte (|v| <= 63).
The vectorised helpers encode whole arrays for the host's segment encoder.
"""

from __future__ import annotations

import numpy as np

MAX_VARINT_BYTES = 10  # enough for any value below 2**64


class VarintError(ValueError):
    """Truncated, overlong or out-of-range varint."""


def zigzag(value: int) -> int:
    return value << 1 if value >= 0 else ((-value) << 1) - 1


def unzigzag(value: int) -> int:
    return (value >> 1) ^ -(value & 1)


def encode_uvarint(value: int) -> bytes:
    if value < 0 or value >= 1 << 64:
        raise VarintError(f"uvarint out of range: {value}")
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def encode_svarint(value: int) -> bytes:
    return encode_uvarint(zigzag(value))


def decode_uvarint(buf: bytes | bytearray | memoryview, pos: int) -> tuple[int, int]:
    """Return ``(value, next_pos)``; raises :class:`VarintError` when truncated or overlong."""
    value = 0
    shift = 0
    end = len(buf)
    while True:
        if pos >= end:
            raise VarintError("truncated varint")
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos
        shift += 7
        if shift >= 7 * MAX_VARINT_BYTES:
            raise VarintError("varint longer than 10 bytes")


def decode_svarint(buf: bytes | bytearray | memoryview, pos: int) -> tuple[int, int]:
    value, pos = decode_uvarint(buf, pos)
    return unzigzag(value), pos


# ------------------------------------------------------------------ vectorised


def zigzag_array(values: np.ndarray) -> np.ndarray:
    """Zigzag of an int64 array as uint64."""
    v = np.asarray(values, dtype=np.int64)
    return ((v << 1) ^ (v >> 63)).astype(np.uint64)


def uvarint_lengths(values: np.ndarray) -> np.ndarray:
    """Encoded length in bytes of each uint64 value (1..10)."""
    v = np.asarray(values, dtype=np.uint64)
    n = np.ones(v.shape, dtype=np.int64)
    for k in range(1, MAX_VARINT_BYTES):
        n += v >= np.uint64(1 << (7 * k))
    return n


def scatter_uvarints(
    out: np.ndarray, positions: np.ndarray, values: np.ndarray, lengths: np.ndarray
) -> None:
    """Write each ``values[i]`` as a varint of ``lengths[i]`` bytes at ``out[positions[i]:]``.

    ``lengths`` may be 0 for fields that are absent; those entries write nothing.
    """
    v = np.asarray(values, dtype=np.uint64)
    for k in range(int(lengths.max(initial=0))):
        sel = lengths > k
        if not sel.any():
            break
        chunk = (v[sel] >> np.uint64(7 * k)) & np.uint64(0x7F)
        more = (lengths[sel] > k + 1).astype(np.uint64) << np.uint64(7)
        out[positions[sel] + k] = (chunk | more).astype(np.uint8)
