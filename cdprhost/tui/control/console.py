"""The console's commands: one G-code line (as an operator types it at a printer) read into
one machine operation (pure). The backend carries the operation out through
:mod:`cdprhost.machine` and answers in lines.

The device does not speak G-code (it takes framed protocol messages), so the console
offers the G-code words operators know, each mapped to one machine operation; anything
else is refused with the list of what is understood.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.line_parser import command_name, parse_line

HELP = (
    ("G28", "home: drivers on, modules to their endstops"),
    ("G0/G1 X Y Z", "straight move (G-code frame; missing axes stay), checked first"),
    ("M104 S / M140 S", "hotend / bed target °C (M109 / M190 also wait)"),
    ("M105", "temperatures"),
    ("M114", "position (G-code and machine frame) and steps"),
    ("M115", "device identity"),
    ("M17 / M18 / M84", "drivers on / off"),
    ("M220 S / M221 S", "speed / flow override of the running print, percent (10-500)"),
    ("M112", "emergency stop: motion and heaters off at once; drivers stay on (M18 releases)"),
    ("M999", "clear the stop (after M112 or a device fault)"),
    ("help", "this list"),
)


@dataclass(frozen=True)
class ConsoleCommand:
    op: str  # home move heaters temps position identity enable motors_off estop clear help
    # speed flow (overrides of the running print)
    text: str
    values: dict[str, float] = field(default_factory=dict)
    wait: bool = False

    @property
    def moves(self) -> bool:
        """Does it move the machine or change its heaters (refused while a print runs)?"""
        return self.op in ("home", "move", "heaters", "enable", "motors_off")


class ConsoleError(ValueError):
    """A console line that cannot be carried out; the message says why."""


def parse_command(text: str) -> ConsoleCommand:
    raw = text.strip()
    if raw.lower() in ("help", "?"):
        return ConsoleCommand("help", raw)
    try:
        parsed = parse_line(raw, 1, "console", strict_params=frozenset({"G0", "G1", "M104"}))
    except GcodeError as exc:
        raise ConsoleError(exc.reason) from None
    if not parsed.words:
        raise ConsoleError("nothing to send")
    name = command_name(parsed.words[0]).upper()
    params = {w.letter: w.value for w in parsed.words[1:] if w.value is not None}
    if name == "G28":
        return ConsoleCommand("home", raw)
    if name in ("G0", "G1"):
        axes = {k.lower(): float(v) for k, v in params.items() if k in "XYZ"}
        if not axes:
            raise ConsoleError(f"{name} needs at least one of X, Y, Z")
        if "F" in params:
            axes["f"] = float(params["F"])
        return ConsoleCommand("move", raw, axes)
    if name in ("M220", "M221"):
        if "S" not in params:
            raise ConsoleError(f"{name} needs S (percent, 10-500)")
        what = "speed" if name == "M220" else "flow"
        return ConsoleCommand(what, raw, {"percent": float(params["S"])})
    if name in ("M104", "M109", "M140", "M190"):
        if "S" not in params:
            raise ConsoleError(f"{name} needs S (target °C)")
        heater = "hotend" if name in ("M104", "M109") else "bed"
        return ConsoleCommand(
            "heaters", raw, {heater: float(params["S"])}, name in ("M109", "M190")
        )
    simple = {
        "M105": "temps",
        "M114": "position",
        "M115": "identity",
        "M17": "enable",
        "M18": "motors_off",
        "M84": "motors_off",
        "M112": "estop",
        "M999": "clear",
    }
    if name in simple:
        return ConsoleCommand(simple[name], raw)
    known = ", ".join(c for c, _ in HELP[:-1])
    raise ConsoleError(f"{name} is not a console command (known: {known}; type help)")
