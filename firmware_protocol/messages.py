"""The message set: one table of typed, bounded fields (the host's commands in
:mod:`firmware_protocol.host_messages`, the device's reports in
:mod:`firmware_protocol.device_messages`, their base in
:mod:`firmware_protocol.message_base`), indexed here by opcode.

A DATA payload is a sequence of messages, each starting with an opcode byte.
Opcodes 0x80..0xFF are move segments (the low bits are flags, see
:mod:`firmware_protocol.segments`); 0x01..0x3F are host commands; 0x40..0x7F are
device reports. Temperatures are integers in tenths of a degree Celsius.

Every field has a wire type with a fixed width (``u8``; ``u16``/``u32`` unsigned
varints of at most 3/5 bytes; ``i16``/``i32`` zigzag varints; ``text`` a length byte
and ASCII) and, where the protocol fixes one, a value range. The table
(``Message.FIELDS``) is the single source for the codec
(:mod:`firmware_protocol.message_codec`), the device's checks and the C header
(:mod:`firmware_protocol.c_header`); PROTOCOL.md section 4 is its prose.
Ranges that depend on the device (heater count, maximum temperatures, clock) are
named by the ``Ident`` field that announces them and checked by the device.
"""

from __future__ import annotations

# the codes and field types are part of the message table's vocabulary: re-exported here
from firmware_protocol.codes import (
    HEATERS_OFF,
    THERMAL_ERRORS,
    AutotuneFailure,
    BootCause,
    ErrorCode,
    EstopFlag,
    EventCode,
    Flag,
)
from firmware_protocol.device_messages import (
    Boot,
    Caps,
    Error,
    EstopAck,
    Event,
    Flow,
    Health,
    Ident,
    Ring,
    Status,
    StepBudget,
    Stepping,
)
from firmware_protocol.fields import MAX_TEXT, TYPE_RANGE, F, Field, MessageError
from firmware_protocol.host_messages import (
    Autotune,
    ClearFault,
    Configure,
    Dwell,
    EmergencyStop,
    Enable,
    Flush,
    GetCaps,
    GetStatus,
    HeaterLease,
    Hello,
    Home,
    Identify,
    Segment,
    SetFan,
    SetHeater,
    SetLimits,
    SetPid,
    SetPosition,
    WaitHeater,
)
from firmware_protocol.message_base import (
    AUTOTUNE_CYCLES_RANGE,
    BED,
    DWELL_MAX_S,
    GAIN_SCALE,
    HOTEND,
    LEASE_MS_RANGE,
    MAX_EVENT_VALUES,
    MINOR_BUDGET,
    MINOR_RING,
    MINOR_SAFETY,
    MINOR_STEPPING,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    TOLERANCE_DC_RANGE,
    WATCHDOG_MS_DEFAULT,
    WATCHDOG_MS_RANGE,
    Message,
)

MESSAGES: tuple[type[Message], ...] = (
    Identify,
    GetStatus,
    ClearFault,
    Flush,
    Hello,
    EmergencyStop,
    Configure,
    SetPosition,
    Enable,
    Home,
    Dwell,
    SetHeater,
    SetFan,
    WaitHeater,
    SetLimits,
    SetPid,
    HeaterLease,
    GetCaps,
    Autotune,
    Ident,
    Status,
    Event,
    Error,
    Boot,
    EstopAck,
    Flow,
    Health,
    Caps,
    Stepping,
    Ring,
    StepBudget,
)
_BY_OPCODE: dict[int, type[Message]] = {cls.OPCODE: cls for cls in MESSAGES}

__all__ = [
    "AUTOTUNE_CYCLES_RANGE",
    "BED",
    "DWELL_MAX_S",
    "GAIN_SCALE",
    "HEATERS_OFF",
    "HOTEND",
    "LEASE_MS_RANGE",
    "MAX_EVENT_VALUES",
    "MAX_TEXT",
    "MESSAGES",
    "MINOR_BUDGET",
    "MINOR_RING",
    "MINOR_SAFETY",
    "MINOR_STEPPING",
    "PROTOCOL_MAJOR",
    "PROTOCOL_MINOR",
    "THERMAL_ERRORS",
    "TOLERANCE_DC_RANGE",
    "TYPE_RANGE",
    "WATCHDOG_MS_DEFAULT",
    "WATCHDOG_MS_RANGE",
    "Autotune",
    "AutotuneFailure",
    "Boot",
    "BootCause",
    "Caps",
    "ClearFault",
    "Configure",
    "Dwell",
    "EmergencyStop",
    "Enable",
    "Error",
    "ErrorCode",
    "EstopAck",
    "EstopFlag",
    "Event",
    "EventCode",
    "F",
    "Field",
    "Flag",
    "Flow",
    "Flush",
    "GetCaps",
    "GetStatus",
    "Health",
    "HeaterLease",
    "Hello",
    "Home",
    "Ident",
    "Identify",
    "Message",
    "MessageError",
    "Ring",
    "Segment",
    "SetFan",
    "SetHeater",
    "SetLimits",
    "SetPid",
    "SetPosition",
    "Status",
    "StepBudget",
    "Stepping",
    "WaitHeater",
]
