"""Frames on the wire and a streaming deframer that resynchronises after garbage.

Layout (all multi-byte fields big-endian; see PROTOCOL.md section 2)::

    0      SYNC  0xA5
    1      LEN   payload length, 0..MAX_PAYLOAD
    2      KIND  DATA=1, ACK=2, NAK=3, URGENT=4
    3      SEQ   sequence number of a DATA frame (0 otherwise)
    4      ACK   next DATA sequence number the sender expects from its peer
    5      HCRC  CRC-8/SMBUS over bytes 1..4
    6..    PAYLOAD (LEN bytes)
    6+LEN  CRC   CRC-32/ISO-HDLC over bytes 1..5+LEN (4 bytes, big-endian)
    10+LEN END   0x5A

No byte stuffing: the header check rejects false SYNC bytes inside payloads, the
CRC-32 the rest, and END turns a dropped byte into a certain rejection because
the byte that slides into END's place is the next frame's SYNC.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from firmware_protocol.crc import crc8, crc32

SYNC = 0xA5
END = 0x5A
HEADER_LEN = 6
CRC_LEN = 4
OVERHEAD = HEADER_LEN + CRC_LEN + 1
MAX_PAYLOAD = 248


class Kind(IntEnum):
    DATA = 1
    ACK = 2
    NAK = 3
    URGENT = 4


@dataclass(frozen=True)
class Frame:
    kind: Kind
    seq: int
    ack: int
    payload: bytes = b""


def encode_frame(kind: int, seq: int, ack: int, payload: bytes = b"") -> bytes:
    """Bytes of one frame. ``seq`` and ``ack`` are taken modulo 256."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    head = bytes((len(payload), int(kind), seq & 0xFF, ack & 0xFF))
    body = head + bytes((crc8(head),)) + payload
    return bytes((SYNC,)) + body + crc32(body).to_bytes(4, "big") + bytes((END,))


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one frame (for tests and worked examples); raises ValueError."""
    frames = Deframer().feed(data)
    if len(frames) != 1:
        raise ValueError("not exactly one valid frame")
    return frames[0]


class Deframer:
    """Turn an arbitrary byte stream into valid frames; count what it rejects.

    A candidate starts at each SYNC. It is rejected (and the scan resumes one byte
    after that SYNC, so a real frame hidden behind garbage is still found) when
    the header check fails, LEN is too large, the kind is unknown, the CRC-32
    differs, or END is missing. An incomplete candidate waits for more bytes unless
    a complete valid frame already follows it.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames = 0
        self.bad_headers = 0
        self.bad_frames = 0  # header fine, CRC-32 or END wrong
        self.garbage_bytes = 0
        self.rejected: list[
            tuple[int, int]
        ] = []  # (kind, seq) of frames with a good header and a bad body

    @property
    def pending(self) -> int:
        return len(self._buf)

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes | bytearray) -> list[Frame]:
        buf = self._buf
        buf += data
        out: list[Frame] = []
        pos = 0
        n = len(buf)
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                self.garbage_bytes += n - pos
                pos = n
                break
            self.garbage_bytes += i - pos
            pos = i
            if n - pos < HEADER_LEN:
                break
            length = buf[pos + 1]
            kind = buf[pos + 2]
            if (
                crc8(buf[pos + 1 : pos + 5]) != buf[pos + 5]
                or length > MAX_PAYLOAD
                or not 1 <= kind <= 4
            ):
                self.bad_headers += 1
                self.garbage_bytes += 1
                pos += 1
                continue
            total = OVERHEAD + length
            if n - pos < total:
                # A false header can claim a long payload; if a complete valid frame
                # already sits behind it, the candidate was garbage: move on.
                later = self._complete_frame_after(buf, pos + 1, n)
                if later < 0:
                    break
                self.bad_headers += 1
                self.garbage_bytes += later - pos
                pos = later
                continue
            end = pos + HEADER_LEN + length
            if buf[end + CRC_LEN] != END or crc32(buf[pos + 1 : end]) != int.from_bytes(
                buf[end : end + CRC_LEN], "big"
            ):
                self.bad_frames += 1
                self.garbage_bytes += 1
                self.rejected.append((kind, buf[pos + 3]))
                pos += 1
                continue
            out.append(Frame(Kind(kind), buf[pos + 3], buf[pos + 4], bytes(buf[pos + 6 : end])))
            self.frames += 1
            pos += total
        del buf[:pos]
        return out

    @staticmethod
    def _complete_frame_after(buf: bytearray, start: int, n: int) -> int:
        """Offset of the first complete, valid frame at or after ``start`` (-1 if none)."""
        i = buf.find(SYNC, start)
        while 0 <= i <= n - OVERHEAD:
            length = buf[i + 1]
            end = i + HEADER_LEN + length
            if (
                length <= MAX_PAYLOAD
                and end + CRC_LEN + 1 <= n
                and crc8(buf[i + 1 : i + 5]) == buf[i + 5]
                and buf[end + CRC_LEN] == END
                and crc32(buf[i + 1 : end]) == int.from_bytes(buf[end : end + CRC_LEN], "big")
            ):
                return i
            i = buf.find(SYNC, i + 1)
        return -1
