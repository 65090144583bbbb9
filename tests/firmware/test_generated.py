"""The firmware's generated headers follow their Python definitions."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import load_script

TOOLS = Path(__file__).resolve().parents[2] / "firmware" / "tools"


def _tool(name: str):
    return load_script(TOOLS / f"{name}.py", name)


@pytest.mark.parametrize(
    "name", ["gen_protocol_header", "gen_thermistor_table", "gen_thermal_plant"]
)
def test_checked_in_header_is_current(name):
    tool = _tool(name)
    assert tool.OUT.read_text() if hasattr(tool, "OUT") else tool.HEADER.read_text()
    assert tool.main(["--check"]) == 0, f"stale: run python firmware/tools/{name}.py"


def test_protocol_header_names_every_opcode_and_layout():
    """Every opcode is in cdpr_protocol.h; every host message has its descriptors."""
    from firmware_protocol import messages as m

    tool = _tool("gen_protocol_header")
    text, cdpr = tool.render(), tool.outputs()[tool.CDPR_HEADER]
    for op, cls in m._BY_OPCODE.items():
        assert re.search(rf"#define CDPR_OP_\w+ 0x{op:02X}\n", cdpr), cls.__name__
    for cls in tool._host_messages():
        name = tool._name(cls)
        assert f"#define OP_{name} CDPR_OP_{name}\n" in text
        assert f"#define NFIELDS_{name} {len(cls.FIELDS)}\n" in text
    # HELLO: nonce u16 (1..65535) then major u8 (type codes 1 and 0), one value each
    assert re.search(r"FIELDS_HELLO \\\n    \{1, 1, -1, 1L, 65535UL\} /\* nonce \*/", text)
    assert "#define PROTO_MAJOR CDPR_PROTOCOL_MAJOR" in text
    assert f"#define CDPR_PROTOCOL_MAJOR {m.PROTOCOL_MAJOR}" in cdpr


def test_a_changed_table_makes_the_check_fail(monkeypatch):
    tool = _tool("gen_protocol_header")
    from firmware_protocol import messages as m

    monkeypatch.setattr(m, "PROTOCOL_MINOR", m.PROTOCOL_MINOR + 1)
    assert tool.main(["--check"]) == 1


def test_thermistor_table_is_monotonic_and_matches_beta_3950():
    tool = _tool("gen_thermistor_table")
    rows = re.findall(r"\{(\d+), \(uint16_t\)\((-?\d+)\)\}", tool.render())
    adc = [int(a) for a, _ in rows]
    temps = [int(t) for _, t in rows]
    assert adc == sorted(adc, reverse=True) and temps == sorted(temps)
    assert abs(tool.adc_at(25.0) - 1024 * 100_000 / 104_700) < 1e-6


def test_crc_tables_in_flash_are_the_polynomials():
    """crc.c's byte tables: CRC-32/ISO-HDLC (zlib's) and CRC-8/SMBUS, entry by entry."""
    import zlib

    src = (TOOLS.parent / "src" / "crc.c").read_text()
    body32 = src[src.index("crc32_planes[4][256]") : src.index("crc8_table[256]")]
    planes = [int(x, 16) for x in re.findall(r"0x([0-9A-F]{2})[,\n]", body32)]
    assert len(planes) == 4 * 256  # plane k holds byte k of every entry
    t32 = [sum(planes[256 * k + i] << (8 * k) for k in range(4)) for i in range(256)]
    for i, v in enumerate(t32):  # the register after byte i from 0 (zlib's ~ undone)
        assert v == zlib.crc32(bytes([i]), 0xFFFFFFFF) ^ 0xFFFFFFFF, i
    body8 = src[src.index("crc8_table[256]") :]
    t8 = [int(x, 16) for x in re.findall(r"0x([0-9A-F]{2})[,\n]", body8)][:256]
    for i, v in enumerate(t8):
        c = i
        for _ in range(8):
            c = ((c << 1) ^ 0x07) & 0xFF if c & 0x80 else (c << 1) & 0xFF
        assert v == c, i
