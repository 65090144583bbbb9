"""The two checksums of the wire format.

- CRC-32 (CRC-32/ISO-HDLC, the one of zlib, Ethernet and PNG): reflected polynomial
  0xEDB88320, initial value 0xFFFFFFFF, final XOR 0xFFFFFFFF; check value for
  b"123456789" is 0xCBF43926. Protects a whole frame.
- CRC-8/SMBUS: poly 0x07, init 0x00, not reflected, xorout 0; check value 0xF4.
  Protects the frame header (length, kind, seq, ack) on its own.
"""

from __future__ import annotations

import zlib

CRC32_CHECK = 0xCBF43926
CRC8_CHECK = 0xF4


def _crc8_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC8 = _crc8_table()


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32/ISO-HDLC of ``data`` (zlib's)."""
    return zlib.crc32(data) & 0xFFFFFFFF


def crc32_reference(data: bytes) -> int:
    """Bit-by-bit CRC-32/ISO-HDLC, the definition the fast version is tested against (and
    what a firmware without a table computes)."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def crc8(data: bytes | bytearray | memoryview) -> int:
    """CRC-8/SMBUS of ``data`` (table driven; headers are four bytes)."""
    crc = 0
    for byte in data:
        crc = _CRC8[crc ^ byte]
    return crc
