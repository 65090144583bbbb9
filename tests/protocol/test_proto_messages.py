"""Message codec round trips, and the worked examples of PROTOCOL.md byte for byte."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

import firmware_protocol.messages as M
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.messages import MessageError, decode_messages, encode_messages
from firmware_protocol.segments import SegmentContext

PROTOCOL_MD = Path(M.__file__).with_name("PROTOCOL.md")


def field_values(f: M.Field) -> st.SearchStrategy:
    if f.type == "text":
        return st.text(
            alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=M.MAX_TEXT
        )
    lo, hi = f.range
    one = st.integers(lo, hi)
    if f.count == 1:
        return one
    if f.counted:
        return st.lists(one, max_size=f.count).map(tuple)
    return st.tuples(*[one] * f.count)


def message_strategy(cls: type[M.Message]) -> st.SearchStrategy:
    """Any message of ``cls`` within the table's ranges (masked arrays: 0 where unset)."""
    fields = {f.name: field_values(f) for f in cls.FIELDS}
    masked = [f for f in cls.FIELDS if f.mask]

    def fix(msg: M.Message) -> M.Message:
        for f in masked:
            mask = getattr(msg, f.mask)
            values = tuple(v if mask >> k & 1 else 0 for k, v in enumerate(getattr(msg, f.name)))
            msg = replace(msg, **{f.name: values})
        return msg

    return st.builds(cls, **fields).map(fix)


message_st = st.one_of(
    st.builds(
        M.Segment,
        st.integers(1, 2**32 - 1),
        st.tuples(*[st.integers(-(2**31) + 1, 2**31 - 1)] * 4),
        st.integers(-1, 255),
    ),
    *[message_strategy(cls) for cls in M.MESSAGES],
)


@given(st.lists(message_st, max_size=8))
def test_every_message_sequence_round_trips(msgs):
    ctx_enc, ctx_dec = SegmentContext(), SegmentContext()
    payload = encode_messages(msgs, ctx_enc)
    assert decode_messages(payload, ctx_dec) == msgs
    assert ctx_enc == ctx_dec


@pytest.mark.parametrize(
    "payload",
    [
        b"\x7e",  # unknown opcode
        b"\x41\x01",  # truncated IDENT
        b"\x14\x00",  # truncated SET_HEATER
        b"\xe0\x10",  # reserved segment flags
        b"\x83\x10",  # truncated segment
        b"\x13\x80\x80\x80\x80\x80\x01",  # DWELL: a u32 varint of 6 bytes
        b"\x13\x80\x80\x80\x80\x10",  # DWELL: 2**32 does not fit a u32
        b"\x14\x00\x80\x80\x04",  # SET_HEATER target 65536 over a u16
        b"\x14\x05\x10",  # heater index 5 (the table allows 0..1)
        b"\x15\xc8\x10",  # fan index 200
        b"\x12\x00",  # HOME with an empty mask
        b"\x11\x10",  # ENABLE bit 4
        b"\x07\x10\x00\x00",  # watchdog 16 ms (100..60000)
        b"\x13\x00",  # DWELL of 0 ticks
        b"\x43\x01\x00\x05\x00\x00\x00\x00\x00",  # EVENT with 5 values
        b"\x8a" + b"\xff" * 4 + b"\x1f" + b"\x00\x00",  # segment delta 2**31 (zigzag 2**32-1)
        b"\x8a\x80\x80\x80\x80\x80\x01\x00\x00",  # slider varint of 6 bytes
    ],
)
def test_bad_payloads_raise_and_leave_the_context(payload):
    ctx = SegmentContext(123, (1, 2, 3, 4))
    with pytest.raises(MessageError):
        decode_messages(payload, ctx)
    assert ctx == SegmentContext(123, (1, 2, 3, 4))


def test_predicted_deltas_must_stay_in_the_32_bit_range():
    ctx = SegmentContext(1000, (2**31 - 1, 0, 0, 0))
    with pytest.raises(MessageError):
        decode_messages(b"\x8e\x02\x00\x00", ctx)  # +1 on top of 2**31 - 1
    assert ctx == SegmentContext(1000, (2**31 - 1, 0, 0, 0))


@pytest.mark.parametrize("cls", M.MESSAGES)
def test_encoding_refuses_values_outside_the_table(cls):
    for f in cls.FIELDS:
        if f.type == "text" or f.count > 1:
            continue
        lo, hi = f.range
        good = {g.name: (g.range[0] if g.type != "text" else "") for g in cls.FIELDS}
        for g in cls.FIELDS:
            if g.count > 1:
                good[g.name] = () if g.counted else (0,) * g.count
        for bad in (lo - 1, hi + 1):
            with pytest.raises(MessageError):
                M.encode_message(cls(**{**good, f.name: bad}))


def test_the_c_header_compiles_for_the_host_and_the_avr(tmp_path):
    import shutil
    import subprocess

    from firmware_protocol.c_header import header

    (tmp_path / "cdpr_protocol.h").write_text(header())
    src = tmp_path / "t.c"
    src.write_text(
        '#include "cdpr_protocol.h"\n'
        "int main(void) { cdpr_ident_t i; cdpr_status_t s; (void)i; (void)s;\n"
        "  return CDPR_IDENT_MAX_LEN > CDPR_MAX_PAYLOAD || CDPR_SEGMENT_MAX_LEN != 27; }\n"
    )
    compilers = [c for c in ("cc", "avr-gcc") if shutil.which(c)]
    if not compilers:
        pytest.skip("no C compiler")
    for cc in compilers:
        args = ["-mmcu=atmega2560"] if cc == "avr-gcc" else []
        subprocess.run(
            [
                cc,
                *args,
                "-std=c99",
                "-Wall",
                "-Wextra",
                "-Werror",
                "-I",
                str(tmp_path),
                "-c",
                str(src),
                "-o",
                str(tmp_path / f"{cc}.o"),
            ],
            check=True,
        )


def test_queued_classification():
    assert M.Segment(1, (0, 0, 0, 0)).QUEUED and M.SetHeater(0, 0).QUEUED and M.Home(1).QUEUED
    assert not M.GetStatus().QUEUED and not M.ClearFault().QUEUED and not M.Identify().QUEUED


# ------------------------------------------------------------------ PROTOCOL.md examples


def protocol_examples():
    text = PROTOCOL_MD.read_text(encoding="utf-8")
    blocks = re.findall(r"```frame\n(.*?)```", text, flags=re.S)
    out = []
    for block in blocks:
        lines = [ln.strip() for ln in block.strip().splitlines()]
        name = lines[0].lstrip("# ")
        head = dict(kv.split("=") for kv in lines[1].split())
        messages = [ln[len("message: ") :] for ln in lines if ln.startswith("message: ")]
        hexline = lines[-1]
        out.append(pytest.param(head, messages, bytes.fromhex(hexline), id=name))
    return out


EXAMPLES = protocol_examples()


def test_protocol_md_has_examples():
    assert len(EXAMPLES) >= 8


@pytest.mark.parametrize("head, messages, raw", EXAMPLES)
def test_protocol_md_example(head, messages, raw):
    frames = Deframer().feed(raw)
    assert len(frames) == 1
    f = frames[0]
    assert (f.kind.name, f.seq, f.ack) == (head["kind"], int(head["seq"]), int(head["ack"]))
    decoded = decode_messages(f.payload, SegmentContext())
    assert [repr(m) for m in decoded] == messages
    # and the other way round: the listed messages encode to exactly these bytes
    rebuilt = encode_frame(
        Kind[head["kind"]],
        int(head["seq"]),
        int(head["ack"]),
        encode_messages(decoded, SegmentContext()),
    )
    assert rebuilt == raw
