"""Non-motion commands: modal switches (applied to the state) and command records.

``apply`` returns the items to yield (maybe none) and raises through ``fail`` for
bad values. A command the reader does not execute becomes `UnknownCommand`:
``harmless`` when it is known to change nothing printed here (``HARMLESS``:
reports, progress, bed levelling, driver settings...); any other is unknown, and
the documented policy applies downstream (a warning when checking, skipped when
printing, an error with ``--strict``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Literal, NoReturn

from cdprhost.gcode import firmware_moves, objects
from cdprhost.gcode.classify import Other
from cdprhost.gcode.items import (
    ColdExtrusion,
    DisplayMessage,
    DwellCommand,
    Fan,
    FlowFactor,
    HomeCommand,
    IgnoredParameters,
    MotorsOff,
    PidAutotune,
    ProgramItem,
    SetMotionLimits,
    SetTemperature,
    SpeedFactor,
    ToolSelect,
    UnknownCommand,
    WaitMoves,
)
from cdprhost.gcode.state import ModalState
from cdprhost.gcode.vocabulary import (
    HARMLESS_EXTENDED,
    harmless,
)

Fail = Callable[..., NoReturn]
Params = dict[str, float]
Produced = ProgramItem | list[ProgramItem] | None
Handler = Callable[[int, Params, ModalState, Fail, Other], Produced]


def apply(other: Other, line: int, st: ModalState, fail: Fail) -> list[ProgramItem]:
    """Execute ``other`` on ``st``; return the items it yields."""
    if other.extended is not None:
        return _extended(other, line, st, fail)
    word, p = other.word, other.params
    handler = _HANDLERS.get(word)
    if handler is not None:
        out = handler(line, p, st, fail, other)
        if out is None:
            return []
        return out if isinstance(out, list) else [out]
    if word[0] == "T":
        return [_tool(word, line, fail)]
    if word[0] not in "GM":
        fail(f"no command before '{word}' (a line must start with a G, M or T word)", word[0])
    return [UnknownCommand(line, word, harmless(word, p))]


def _number(p: dict[str, float], letter: str, fail: Fail, *, minimum: float = 0.0) -> float | None:
    v = p.get(letter)
    if v is None:
        return None
    if math.isnan(v):
        fail(f"missing number after {letter}", letter)
    if v < minimum:
        fail(f"{letter}{v:g} is below {minimum:g}", letter)
    return v


def _positive(p: dict[str, float], letter: str, fail: Fail, scale: float = 1.0) -> float | None:
    """A limit value: negative is an error, zero means "not given"."""
    v = _number(p, letter, fail)
    return None if v is None or v == 0 else v * scale


def _tool(word: str, line: int, fail: Fail) -> ProgramItem:
    if word != "T0":
        fail(f"{word}: this machine has a single extruder (only T0)", "T")
    return ToolSelect(line, 0)


def _check_tool(p: dict[str, float], fail: Fail) -> None:
    t = p.get("T")
    if t is not None and t != 0:
        fail(f"T{t:g}: this machine has a single extruder (only T0)", "T")


def _temperature(heater: Literal["hotend", "bed"], wait: bool) -> Handler:
    def handle(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
        _check_tool(p, fail)
        r = _number(p, "R", fail)
        s = _number(p, "S", fail)  # checked even beside R
        target = r if r is not None else s
        if target is None:
            return None
        return _set_target(st, line, heater, target, wait, wait_cooling=wait and r is not None)

    return handle


def _autotune(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """M303 E0 (hotend) / E-1 (bed) S<target> C<cycles> (Marlin's defaults: E0, 150 C, 5)."""
    e = p.get("E", 0.0)
    if math.isnan(e) or e not in (0.0, -1.0):
        fail("E must be 0 (the hotend) or -1 (the bed)", "E")
    target = _number(p, "S", fail)
    cycles = _number(p, "C", fail)
    if cycles is not None and not 3 <= cycles <= 20:
        fail(f"C{cycles:g}: autotune takes 3..20 cycles", "C")
    return PidAutotune(
        line,
        "bed" if e == -1.0 else "hotend",
        150.0 if target is None else target,
        5 if cycles is None else int(cycles),
    )


def _set_target(
    st: ModalState,
    line: int,
    heater: Literal["hotend", "bed"],
    target: float,
    wait: bool,
    wait_cooling: bool = False,
) -> SetTemperature:
    """A heater target, remembered for M116."""
    st.targets[heater] = target
    return SetTemperature(line, heater, target, wait, wait_cooling=wait_cooling)


def _wait_for_heaters(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """M116 (RepRapFirmware): wait until the heaters reach the targets set so far (its P/H
    selections name tools and heaters of bigger machines: all of ours are waited for)."""
    return [SetTemperature(line, h, t, True) for h, t in st.targets.items() if t > 0]


def _fan_on(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    s = _number(p, "S", fail)
    index = _number(p, "P", fail)
    speed = 1.0 if s is None else min(s / 255.0, 1.0)
    return Fan(line, speed, int(index or 0))


def _fan_off(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    index = _number(p, "P", fail)
    return Fan(line, 0.0, int(index or 0))


def _dwell(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    s = _number(p, "S", fail)
    ms = _number(p, "P", fail)
    return DwellCommand(line, s if s is not None else (ms or 0.0) / 1000.0)


def _home(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    st.pos[:3] = st.home
    st.off[:3] = st.home_offsets()[:3]
    return HomeCommand(line, tuple(a for a in "XYZ" if a in p))


def _set_all_zero(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    st.off = st.pos.copy()
    return None


def _motors_off(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    if "S" in p:  # M84 S<seconds>: idle timeout, does not release now
        return UnknownCommand(line, other.word, True)
    if p and not any(a in p for a in "XYZ"):  # M84 E: the extruder motor only
        return UnknownCommand(line, other.word, True)
    return MotorsOff(line)


def _printable(text: str) -> str:
    """Undecodable bytes (kept as surrogates while parsing) become U+FFFD."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def _setter(attr: str, value: object) -> Handler:
    def handle(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
        setattr(st, attr, value)
        return None

    return handle


def _speed_factor(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """M220 S<percent>; B saves the factor, R restores it (Marlin)."""
    if "B" in p:
        st.speed_factor_saved = st.speed_factor
    if "R" in p:
        st.speed_factor = st.speed_factor_saved
    s = _number(p, "S", fail)
    if s is not None:
        if s <= 0:
            fail(f"speed factor S{s:g} must be above 0 %", "S")
        st.speed_factor = s / 100.0
    return SpeedFactor(line, st.speed_factor) if ("S" in p or "R" in p) else None


def _flow_factor(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """M221 S<percent> [T0]."""
    _check_tool(p, fail)
    s = _number(p, "S", fail)
    if s is None:
        return None
    st.flow_factor = s / 100.0
    return FlowFactor(line, st.flow_factor)


_AXES = "XYZE"


def _axes(
    p: Params, fail: Fail, scale: float
) -> tuple[float | None, float | None, float | None, float | None]:
    vals = [_positive(p, a, fail, scale) for a in _AXES]
    return (vals[0], vals[1], vals[2], vals[3])


def _max_accel(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M201, mm/s^2 (inches under G20)
    _check_tool(p, fail)
    return SetMotionLimits(line, "M201", axis_accel=_axes(p, fail, st.scale))


def _max_feedrate(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M203, mm/s
    _check_tool(p, fail)
    return SetMotionLimits(line, "M203", axis_velocity=_axes(p, fail, st.scale))


def _accel(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M204 S (both) | P (print) | T (travel) | R (retract)
    s = _positive(p, "S", fail, st.scale)
    pr = _positive(p, "P", fail, st.scale)
    tr = _positive(p, "T", fail, st.scale)
    return SetMotionLimits(
        line,
        "M204",
        print_accel=pr if pr is not None else s,
        travel_accel=tr if tr is not None else s,
        retract_accel=_positive(p, "R", fail, st.scale),
    )


def _jerk(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M205 X/Y (classic jerk), J (junction deviation)
    xy = [v for v in (_positive(p, "X", fail, st.scale), _positive(p, "Y", fail, st.scale)) if v]
    return SetMotionLimits(
        line,
        "M205",
        corner_velocity=min(xy) if xy else None,
        junction_deviation=_positive(p, "J", fail, st.scale),
    )


def _retraction_settings(length_field: str, speed_field: str) -> Handler:
    """M207 S<length> F<mm/min> (retract; Z hop is not done) and M208 S<extra> F<mm/min>."""

    def handle(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
        length, feed = _number(p, "S", fail), _positive(p, "F", fail, 1 / 60.0)
        changes: dict[str, float] = {}
        if length is not None:
            changes[length_field] = length * st.scale
        if feed is not None:
            changes[speed_field] = feed * st.scale
        st.retraction = replace(st.retraction, **changes)
        hop = p.get("Z")
        if hop is not None and not math.isnan(hop) and hop != 0:  # M207 Z: hop on retract
            return IgnoredParameters(line, "M207", f"Z{hop:g}")  # a warning: no Z hop here
        return None

    return handle


def _cold_extrusion(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M302 [P0|P1] [S<min temp>]
    pv = _number(p, "P", fail)
    s = _number(p, "S", fail)
    if pv is None and s is None:
        return UnknownCommand(line, "M302", True)  # bare M302 reports the setting
    allow = None if pv is None else pv != 0
    if s == 0:
        allow = True
    return ColdExtrusion(line, allow, s)


def _filament_change(
    line: int, p: Params, st: ModalState, fail: Fail, other: Other
) -> Produced:  # M600 [X Y] [Z lift] [E retract]
    def value(letter: str) -> float | None:
        v = p.get(letter)
        return None if v is None or math.isnan(v) else v

    lift, retract = value("Z"), value("E")
    return firmware_moves.filament_change(
        st,
        line,
        xy=(value("X"), value("Y")),
        lift_mm=None if lift is None else abs(lift) * st.scale,
        retract_mm=None if retract is None else abs(retract) * st.scale,
    )


def _volumetric(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """M200 D<filament diameter>: E in mm^3 from here on (D0 or S0: off); T0 only."""
    _check_tool(p, fail)
    d = _number(p, "D", fail)
    s = _number(p, "S", fail)
    if s == 0 or d == 0:
        st.volumetric_scale = 1.0
    elif d is not None:
        st.volumetric_scale = 1.0 / (math.pi * (d * st.scale) ** 2 / 4.0)
    elif s is not None:  # S1: on with the diameter given before (the machine's filament)
        st.volumetric_scale = 1.0 / (math.pi * st.filament_diameter_mm**2 / 4.0)
    return None


def _m486(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    return objects.m486(other.text or "", line, st, fail)


def _g10(line: int, p: Params, st: ModalState, fail: Fail, other: Other) -> Produced:
    """G10 alone is firmware retraction. ``G10 P<tool> S<active> [R<standby>]`` sets tool
    temperatures (RepRapFirmware: tool 0 is our hotend; standby has no meaning with one
    tool); with L it sets CNC work offsets (not done)."""
    keys = set(p)
    if "P" in keys and keys <= {"P", "S", "R"}:
        tool, active = _number(p, "P", fail), _number(p, "S", fail)
        if tool == 0 and active is not None:
            return _set_target(st, line, "hotend", active, False)
        if tool == 0:
            return None  # a standby temperature only
    if keys - {"S"}:
        return UnknownCommand(line, "G10", False, _param_text("G10", p))
    return firmware_moves.retract(st, line)


def _param_text(word: str, p: dict[str, float]) -> str:
    return " ".join([word, *(k if math.isnan(v) else f"{k}{v:g}" for k, v in p.items())])


_HANDLERS: dict[str, Handler] = {
    "M104": _temperature("hotend", False),
    "M109": _temperature("hotend", True),
    "M140": _temperature("bed", False),
    "M190": _temperature("bed", True),
    "M116": _wait_for_heaters,
    "M303": _autotune,
    "M106": _fan_on,
    "M107": _fan_off,
    "G4": _dwell,
    "G28": _home,
    "G92": _set_all_zero,
    "M84": _motors_off,
    "M18": _motors_off,
    "M400": lambda line, p, st, fail, other: WaitMoves(line),
    "M117": lambda line, p, st, fail, other: DisplayMessage(line, _printable(other.text or "")),
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
    "M220": _speed_factor,
    "M221": _flow_factor,
    "M201": _max_accel,
    "M203": _max_feedrate,
    "M204": _accel,
    "M205": _jerk,
    "M207": _retraction_settings("length_mm", "speed_mm_s"),
    "M208": _retraction_settings("extra_mm", "unretract_speed_mm_s"),
    "G10": _g10,
    "G11": lambda line, p, st, fail, other: firmware_moves.unretract(st, line),
    "M302": _cold_extrusion,
    "M600": _filament_change,
    "M486": _m486,
    "M200": _volumetric,
}


# ------------------------------------------------------------------ extended
def _extended(other: Other, line: int, st: ModalState, fail: Fail) -> list[ProgramItem]:
    word, params = other.word, other.extended or {}
    text = f"{word} {other.text or ''}".strip()
    if word.startswith("EXCLUDE_OBJECT"):
        return objects.exclude_object_command(word, params, line, st, fail)
    if word == "SET_VELOCITY_LIMIT":
        return [
            SetMotionLimits(
                line,
                word,
                velocity=_ext_number(params, "VELOCITY", fail),
                print_accel=_ext_number(params, "ACCEL", fail),
                travel_accel=_ext_number(params, "ACCEL", fail),
                corner_velocity=_ext_number(params, "SQUARE_CORNER_VELOCITY", fail),
            )
        ]
    if word == "SET_RETRACTION":
        r = st.retraction

        def given(key: str, old: float) -> float:
            v = _ext_number(params, key, fail)
            return old if v is None else v

        st.retraction = replace(
            r,
            length_mm=given("RETRACT_LENGTH", r.length_mm),
            speed_mm_s=given("RETRACT_SPEED", r.speed_mm_s),
            extra_mm=given("UNRETRACT_EXTRA_LENGTH", r.extra_mm),
            unretract_speed_mm_s=given("UNRETRACT_SPEED", r.unretract_speed_mm_s),
        )
        return []
    return [UnknownCommand(line, word, word in HARMLESS_EXTENDED, text)]


def _ext_number(params: dict[str, str], key: str, fail: Fail) -> float | None:
    raw = params.get(key)
    if raw is None or raw == "":
        return None
    try:
        v = float(raw)
    except ValueError:
        fail(f"malformed number {key}={raw}")
    if not math.isfinite(v) or v < 0:
        fail(f"{key}={raw} must be a number >= 0")
    return v
