"""The G-code vocabulary: which commands are modal, known, harmless or machine-specific.

Sets of command words the reader and :mod:`cdprhost.gcode.commands` consult; no logic
beyond the two predicates.
"""

from __future__ import annotations

from cdprhost.gcode.classify import Other

# Change how later coordinates are read, or move the machine themselves: they end a
# vectorised run.
MODAL = frozenset(
    {
        "G17",
        "G18",
        "G19",
        "G20",
        "G21",
        "G28",
        "G90",
        "G91",
        "M82",
        "M83",
        "M220",
        "M221",
        "G10",
        "G11",
        "M600",
        "M200",
    }
)

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
        "M116",
        "M303",
        "M106",
        "M107",
        "M84",
        "M18",
        "M400",
        "M117",
        "M110",
        "M201",
        "M203",
        "M204",
        "M205",
        "M207",
        "M208",
        "M302",
    }
    | MODAL
)
# Known commands whose parameters may be bare letters (G28 X Y).
FLAG_COMMANDS = frozenset({"G28", "M84", "M18", "M600"})

# Skipping these changes neither geometry nor extrusion. Bed levelling: the
# calibrated kinematics define the bed. Pressure advance, input shaping, driver
# modes, currents: the firmware's business. Reports, progress, display, sounds,
# settings storage, print timers, power.
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
        "M78",
        "M80",
        "M81",
        "M105",
        "M114",
        "M115",
        "M118",
        "M119",
        "M155",
        "M27",
        "M31",
        "M141",
        "M142",
        "M191",
        "M150",
        "M202",
        "M209",
        "M300",
        "M355",
        "M413",
        "M420",
        "M500",
        "M501",
        "M502",
        "M503",
        "M530",
        "M531",
        "M532",
        "M555",
        "M566",
        "M569",
        "M572",
        "M593",
        "M710",
        "M900",
        "M906",
        "M907",
        "M911",
        "M912",
        "M913",
        "M914",
        "M2",
    }
)
_HARMLESS_PREFIX = ("M862.", "G29.")  # Prusa printer/nozzle/firmware checks; levelling variants
# Klipper extended commands known to change nothing printed here.
HARMLESS_EXTENDED = frozenset(
    {
        "SET_PRESSURE_ADVANCE",
        "GET_POSITION",
        "SET_PRINT_STATS_INFO",
        "TIMELAPSE_TAKE_FRAME",
        "BED_MESH_CALIBRATE",
        "BED_MESH_PROFILE",
        "BED_MESH_CLEAR",
        "SET_IDLE_TIMEOUT",
        "RESPOND",
        "SET_LED",
        "SET_INPUT_SHAPER",
        "UPDATE_DELAYED_GCODE",
        "SET_DISPLAY_TEXT",
        "M117",
    }
)

# Machine-specific settings: ignored inside the blocks --retarget replaces (``mute``).
MUTABLE = frozenset(
    {"M220", "M221", "G10", "G11", "M600", "M207", "M208", "SET_RETRACTION", "M201", "M203"}
    | {"M204", "M205", "SET_VELOCITY_LIMIT", "M302"}
)


def is_modal(other: Other) -> bool:
    """True when ``other`` changes how the following coordinates are read (or moves)."""
    return other.word in MODAL or (other.word == "G92" and not other.params)


def harmless(word: str, params: dict[str, float]) -> bool:
    """Whether an unknown command can be skipped without changing the print."""
    return word in HARMLESS or word.startswith(_HARMLESS_PREFIX)
