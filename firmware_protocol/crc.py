"""The two checksums of the wire format.

- CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740): poly 0x1021, init 0xFFFF, not
  reflected, xorout 0; check value for b"123456789" is 0x29B1. Protects a frame.
- CRC-8/SMBUS: poly 0x07, init 0x00, not reflected, xorout 0; check value 0xF4.
  Protects the frame header (length, kind, seq, ack) on its own.
"""

from __future__ import annotations

import binascii

CRC16_CHECK = 0x29B1
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


def crc16(data: bytes | bytearray | memoryview, init: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (binascii.crc_hqx is exactly this polynomial)."""
    return binascii.crc_hqx(data, init)


def crc16_reference(data: bytes) -> int:
    """Bit-by-bit CRC-16/CCITT-FALSE, the definition the fast version is tested against."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def crc8(data: bytes | bytearray | memoryview) -> int:
    """CRC-8/SMBUS of ``data`` (table driven; headers are four bytes)."""
    crc = 0
    for byte in data:
        crc = _CRC8[crc ^ byte]
    return crc
