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


# ------------------------------------------------------------------ bounded (the wire's field types)


def max_bytes(bits: int) -> int:
    """A varint of ``bits`` bits takes at most ceil(bits / 7) bytes."""
    return (bits + 6) // 7


def decode_ubounded(buf: bytes | bytearray | memoryview, pos: int, bits: int) -> tuple[int, int]:
    """An unsigned varint that must fit ``bits`` bits in at most ``ceil(bits / 7)`` bytes.

    This is what a microcontroller's fixed-width parser accepts: a longer encoding or a
    value over the width raises :class:`VarintError` (never an unbounded integer)."""
    value = 0
    shift = 0
    end = len(buf)
    limit = 7 * max_bytes(bits)
    while True:
        if pos >= end:
            raise VarintError("truncated varint")
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            break
        if shift >= limit:
            raise VarintError(f"varint longer than {max_bytes(bits)} bytes for a {bits}-bit field")
    if value >> bits:
        raise VarintError(f"value {value} does not fit a {bits}-bit field")
    return value, pos


def decode_sbounded(buf: bytes | bytearray | memoryview, pos: int, bits: int) -> tuple[int, int]:
    """A zigzag varint of a signed ``bits``-bit field (two's complement range)."""
    value, pos = decode_ubounded(buf, pos, bits)
    return (value >> 1) ^ -(value & 1), pos


def decode_uvarint(buf: bytes | bytearray | memoryview, pos: int) -> tuple[int, int]:
    """Any varint below 2**64 (10 bytes at most); ``(value, next_pos)``."""
    return decode_ubounded(buf, pos, 64)


def decode_svarint(buf: bytes | bytearray | memoryview, pos: int) -> tuple[int, int]:
    return decode_sbounded(buf, pos, 64)


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
