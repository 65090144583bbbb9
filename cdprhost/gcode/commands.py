"""Non-motion commands: modal switches (applied to the state) and command records.

``apply`` returns the record to yield (or None) and raises through ``fail`` for
bad values. Unknown commands become `Unknown`, flagged harmless when skipping them
changes nothing that is printed (see ``HARMLESS`` and the README).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NoReturn

from cdprhost.gcode.classify import Other
from cdprhost.gcode.items import (
    Command,
    Dwell,
    Fan,
    Home,
    Message,
    MotorsOff,
    SetTemperature,
    ToolSelect,
    Unknown,
    WaitMoves,
)
from cdprhost.gcode.state import ModalState

# Change how later coordinates are read: they end a vectorised run.
MODAL = frozenset({"G17", "G18", "G19", "G20", "G21", "G28", "G90", "G91", "M82", "M83"})

# Parameters are checked strictly (bad numbers are errors) for these commands.
KNOWN = frozenset(
    {
        "G0",
        "G1",
        "G2",
        "G3",
        "G4",
        "G92",
        "M104",
        "M109",
        "M140",
        "M190",
        "M106",
        "M107",
        "M84",
        "M18",
        "M400",
        "M117",
        "M110",
        "G28",
    }
    | MODAL
)
# Known commands whose parameters may be bare letters (G28 X Y).
FLAG_COMMANDS = frozenset({"G28", "M84", "M18"})

# Skipping these changes neither geometry nor extrusion. Limits, jerk and pressure
# advance: the host plans with its own profile. Bed levelling: the calibrated
# kinematics define the bed. Reports, progress, display, sounds, settings storage.
HARMLESS = frozenset(
    {
        "G29",
        "G80",
        "G81",
        "M17",
        "M73",
        "M75",
        "M76",
        "M77",
        "M105",
        "M114",
        "M115",
        "M118",
        "M119",
        "M155",
        "M27",
        "M31",
        "M141",
        "M191",
        "M150",
        "M201",
        "M202",
        "M203",
        "M204",
        "M205",
        "M207",
        "M208",
        "M209",
        "M220",
        "M300",
        "M355",
        "M413",
        "M486",
        "M500",
        "M501",
        "M502",
        "M503",
        "M530",
        "M531",
        "M532",
        "M566",
        "M572",
        "M593",
        "M710",
        "M900",
        "M907",
        "M2",
    }
)
_HARMLESS_PREFIX = ("M862.",)  # Prusa printer/nozzle/firmware checks

Fail = Callable[..., NoReturn]


def is_modal(other: Other) -> bool:
    """True when ``other`` changes how the following coordinates are read."""
    return other.word in MODAL or (other.word == "G92" and not other.params)


def harmless(word: str, params: dict[str, float]) -> bool:
    """Whether an unknown command can be skipped without changing the print."""
    if word in HARMLESS or word.startswith(_HARMLESS_PREFIX):
        return True
    if word == "M221":  # flow factor: harmless only when it restores 100 %
        return params.get("S", 100.0) == 100.0
    if word == "M200":  # volumetric extrusion: harmless only when switched off
        return params.get("D", math.nan) == 0.0
    return False


def apply(other: Other, line: int, st: ModalState, fail: Fail) -> Command | None:
    """Execute ``other`` on ``st``; return its record, if any."""
    word, p = other.word, other.params
    handler = _HANDLERS.get(word)
    if handler is not None:
        return handler(line, p, st, fail, other)
    if word[0] == "T":
        return _tool(word, line, fail)
    if word[0] not in "GM":
        fail(f"no command before {word!r} (a line must start with a G, M or T word)", word[0])
    return Unknown(line, word, harmless(word, p))


def _number(p: dict[str, float], letter: str, fail: Fail, *, minimum: float = 0.0) -> float | None:
    v = p.get(letter)
    if v is None:
        return None
    if math.isnan(v):
        fail(f"missing number after {letter}", letter)
    if v < minimum:
        fail(f"{letter}{v:g} is below {minimum:g}", letter)
    return v


def _tool(word: str, line: int, fail: Fail) -> Command:
    if word != "T0":
        fail(f"{word}: this machine has a single extruder (only T0)", "T")
    return ToolSelect(line, 0)


def _check_tool(p: dict[str, float], fail: Fail) -> None:
    t = p.get("T")
    if t is not None and t != 0:
        fail(f"T{t:g}: this machine has a single extruder (only T0)", "T")


def _temperature(heater: str, wait: bool):
    def handle(line, p, st, fail, other):
        _check_tool(p, fail)
        r = _number(p, "R", fail)
        s = _number(p, "S", fail)
        if r is not None:
            return SetTemperature(line, heater, r, wait, wait_cooling=wait)
        if s is not None:
            return SetTemperature(line, heater, s, wait)
        return None

    return handle


def _fan_on(line, p, st, fail, other):
    s = _number(p, "S", fail)
    index = _number(p, "P", fail)
    speed = 1.0 if s is None else min(s / 255.0, 1.0)
    return Fan(line, speed, int(index or 0))


def _fan_off(line, p, st, fail, other):
    index = _number(p, "P", fail)
    return Fan(line, 0.0, int(index or 0))


def _dwell(line, p, st, fail, other):
    s = _number(p, "S", fail)
    ms = _number(p, "P", fail)
    return Dwell(line, s if s is not None else (ms or 0.0) / 1000.0)


def _home(line, p, st, fail, other):
    st.pos[:3] = st.home
    st.off[:3] = 0.0
    return Home(line, tuple(a for a in "XYZ" if a in p))


def _set_all_zero(line, p, st, fail, other):
    st.off = st.pos.copy()


def _motors_off(line, p, st, fail, other):
    if "S" in p:  # M84 S<seconds>: idle timeout, does not release now
        return Unknown(line, other.word, True)
    return MotorsOff(line)


def _printable(text: str) -> str:
    """Undecodable bytes (kept as surrogates while parsing) become U+FFFD."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def _setter(attr: str, value):
    def handle(line, p, st, fail, other):
        setattr(st, attr, value)

    return handle


_HANDLERS: dict[str, Callable] = {
    "M104": _temperature("hotend", False),
    "M109": _temperature("hotend", True),
    "M140": _temperature("bed", False),
    "M190": _temperature("bed", True),
    "M106": _fan_on,
    "M107": _fan_off,
    "G4": _dwell,
    "G28": _home,
    "G92": _set_all_zero,
    "M84": _motors_off,
    "M18": _motors_off,
    "M400": lambda line, p, st, fail, other: WaitMoves(line),
    "M117": lambda line, p, st, fail, other: Message(line, _printable(other.text or "")),
    "M110": lambda line, p, st, fail, other: None,
    "G90": _setter("relative", False),
    "G91": _setter("relative", True),
    "M82": _setter("relative_e", False),
    "M83": _setter("relative_e", True),
    "G20": _setter("scale", 25.4),
    "G21": _setter("scale", 1.0),
    "G17": _setter("plane", 17),
    "G18": _setter("plane", 18),
    "G19": _setter("plane", 19),
}
