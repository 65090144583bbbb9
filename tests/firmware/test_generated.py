"""The firmware's generated headers follow their Python definitions."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parents[2] / "firmware" / "tools"


def _tool(name: str):
    spec = importlib.util.spec_from_file_location(name, TOOLS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["gen_protocol_header", "gen_thermistor_table"])
def test_checked_in_header_is_current(name):
    tool = _tool(name)
    assert tool.OUT.read_text() if hasattr(tool, "OUT") else tool.HEADER.read_text()
    assert tool.main(["--check"]) == 0, f"stale: run python firmware/tools/{name}.py"


def test_protocol_header_names_every_opcode_and_layout():
    from firmware_protocol import messages as m

    text = _tool("gen_protocol_header").render()
    for op, cls in m._BY_OPCODE.items():
        assert re.search(rf"#define OP_\w+ 0x{op:02X}\n", text), cls.__name__
    assert '#define LAYOUT_HELLO "ubb"' in text
    assert '#define LAYOUT_STATUS "buuuu4susubbbbuuuu"' in text
    assert f"#define PROTO_MAJOR {m.PROTOCOL_MAJOR}" in text


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
