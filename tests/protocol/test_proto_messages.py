"""Message codec round trips, and the worked examples of PROTOCOL.md byte for byte."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

import firmware_protocol.messages as M
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.messages import MessageError, decode_messages, encode_messages
from firmware_protocol.segments import SegmentContext

PROTOCOL_MD = Path(M.__file__).with_name("PROTOCOL.md")

u8 = st.integers(0, 255)
uv = st.integers(0, 2**40)
sv = st.integers(-(2**40), 2**40)
text = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=40)
sv4 = st.tuples(sv, sv, sv, sv)

message_st = st.one_of(
    st.builds(
        M.Segment,
        st.integers(1, 2**32 - 1),
        st.tuples(*[st.integers(-(2**31) + 1, 2**31 - 1)] * 4),
        st.integers(-1, 255),
    ),
    st.just(M.Identify()),
    st.just(M.GetStatus()),
    st.just(M.ClearFault()),
    st.just(M.EmergencyStop()),
    st.builds(M.Hello, uv, u8, u8),
    st.builds(M.SetPosition, sv4),
    st.builds(M.Enable, u8),
    st.integers(0, 7).flatmap(
        lambda mask: st.builds(
            M.Home,
            st.just(mask),
            st.tuples(*[sv if mask >> k & 1 else st.just(0) for k in range(3)]),
        )
    ),
    st.builds(M.Dwell, uv),
    st.builds(M.SetHeater, u8, uv),
    st.builds(M.SetFan, u8, u8),
    st.builds(M.WaitHeater, u8, uv),
    st.builds(M.Ident, uv, u8, u8, uv, text, text, u8, uv, uv, uv, u8, u8, u8, uv, uv, uv, uv),
    st.builds(M.Status, u8, uv, uv, uv, uv, sv4, sv, uv, sv, uv, u8, u8, u8, u8, uv, uv, uv, uv),
    st.builds(M.Event, u8, uv, st.lists(sv, max_size=5).map(tuple)),
    st.builds(M.Error, u8, uv, uv, u8, sv),
    st.builds(M.Boot, uv, u8, u8, u8, u8, uv, uv),
    st.builds(M.EstopAck, uv, uv),
    st.builds(M.Flow, u8, uv, uv, uv),
)


@given(st.lists(message_st, max_size=8))
def test_every_message_sequence_round_trips(msgs):
    ctx_enc, ctx_dec = SegmentContext(), SegmentContext()
    payload = encode_messages(msgs, ctx_enc)
    assert decode_messages(payload, ctx_dec) == msgs
    assert ctx_enc == ctx_dec


@pytest.mark.parametrize("payload", [b"\x7e", b"\x41\x01", b"\x14\x00", b"\xe0\x10", b"\x83\x10"])
def test_bad_payloads_raise_and_leave_the_context(payload):
    ctx = SegmentContext(123, (1, 2, 3, 4))
    with pytest.raises(MessageError):
        decode_messages(payload, ctx)
    assert ctx == SegmentContext(123, (1, 2, 3, 4))


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
