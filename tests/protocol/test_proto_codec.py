"""Checksums and compact integers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocol.crc import CRC8_CHECK, CRC32_CHECK, crc8, crc32, crc32_reference
from firmware_protocol.varint import (
    VarintError,
    decode_svarint,
    decode_uvarint,
    encode_svarint,
    encode_uvarint,
    scatter_uvarints,
    unzigzag,
    uvarint_lengths,
    zigzag,
    zigzag_array,
)


def test_crc_check_values():
    assert crc32(b"123456789") == CRC32_CHECK == 0xCBF43926
    assert crc32_reference(b"123456789") == 0xCBF43926
    assert crc8(b"123456789") == CRC8_CHECK == 0xF4
    assert crc32(b"") == 0


@given(st.binary(max_size=300))
def test_fast_crc32_matches_the_bitwise_definition(data):
    assert crc32(data) == crc32_reference(data)


@given(st.binary(min_size=1, max_size=64), st.integers(0, 8 * 64 - 1))
def test_crc32_detects_every_single_bit_flip(data, bit):
    bit %= 8 * len(data)
    flipped = bytearray(data)
    flipped[bit // 8] ^= 1 << (bit % 8)
    assert crc32(bytes(flipped)) != crc32(data)


@pytest.mark.parametrize(
    "value, encoded",
    [(0, "00"), (1, "01"), (127, "7F"), (128, "80 01"), (300, "AC 02"), (16384, "80 80 01")],
)
def test_uvarint_examples(value, encoded):
    assert encode_uvarint(value) == bytes.fromhex(encoded)


@pytest.mark.parametrize(
    "value, encoded",
    [
        (0, "00"),
        (-1, "01"),
        (1, "02"),
        (-2, "03"),
        (63, "7E"),
        (-64, "7F"),
        (64, "80 01"),
        (400, "A0 06"),
        (-300, "D7 04"),
    ],
)
def test_svarint_examples(value, encoded):
    assert encode_svarint(value) == bytes.fromhex(encoded)


@given(st.integers(0, 2**64 - 1))
def test_uvarint_round_trip(value):
    data = encode_uvarint(value)
    assert decode_uvarint(data + b"\x55", 0) == (value, len(data))


@given(st.integers(-(2**62), 2**62))
def test_svarint_round_trip_and_zigzag(value):
    assert unzigzag(zigzag(value)) == value
    data = encode_svarint(value)
    assert decode_svarint(data, 0) == (value, len(data))


def test_varint_errors():
    with pytest.raises(VarintError):
        decode_uvarint(b"\x80\x80", 0)
    with pytest.raises(VarintError):
        decode_uvarint(b"\x80" * 11, 0)
    with pytest.raises(VarintError):
        encode_uvarint(-1)


@given(st.lists(st.integers(-(2**40), 2**40), min_size=1, max_size=50))
def test_vectorised_varints_match_scalar(values):
    z = zigzag_array(np.array(values))
    assert [int(v) for v in z] == [zigzag(v) for v in values]
    lens = uvarint_lengths(z)
    assert [int(n) for n in lens] == [len(encode_svarint(v)) for v in values]
    pos = np.concatenate([[0], np.cumsum(lens)[:-1]])
    out = np.zeros(int(lens.sum()), dtype=np.uint8)
    scatter_uvarints(out, pos, z, lens)
    assert out.tobytes() == b"".join(encode_svarint(v) for v in values)
