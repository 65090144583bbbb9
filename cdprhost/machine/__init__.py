"""Operations on a connected machine, used by the print job, the calibration wizard, the CLI
and the TUI alike (one way to do each): :class:`Machine` over a handshaken link."""

from cdprhost.machine.faults import DeviceFaulted
from cdprhost.machine.operations import Machine, MoveResult, NotHomed
from cdprhost.machine.prepare import DeviceCheck, DeviceNotReady, prepare_device

__all__ = [
    "DeviceCheck",
    "DeviceFaulted",
    "DeviceNotReady",
    "Machine",
    "MoveResult",
    "NotHomed",
    "prepare_device",
]
