"""Link failures. Every wait in the link ends in one of these, with a clear message."""

from __future__ import annotations

from cdprhost.errors import CdprError


class LinkError(CdprError):
    """Base of all serial-link failures (exit status 1)."""


class PortNotFound(LinkError):
    """The port path does not exist (bad input: exit status 2)."""

    exit_code = 2


class PortBusy(LinkError):
    """Another process holds the port (opened exclusively)."""


class PortVanished(LinkError):
    """The port went away or failed with an I/O error (unplugged, EIO)."""


class DeviceSilent(LinkError):
    """No valid frame from the device within the timeout; ``last_segment`` as last reported."""

    def __init__(self, message: str, *, last_segment: int = 0, last_item: int = 0):
        super().__init__(message)
        self.last_segment = last_segment
        self.last_item = last_item


class ProtocolMismatch(LinkError):
    """The device speaks another protocol major version."""

    def __init__(
        self, message: str, *, device_version: tuple[int, int], host_version: tuple[int, int]
    ):
        super().__init__(message)
        self.device_version = device_version
        self.host_version = host_version


class DeviceReset(LinkError):
    """The device restarted mid-session; ``last_segment`` is the last segment it executed."""

    def __init__(self, message: str, *, last_segment: int, last_item: int, exact: bool):
        super().__init__(message)
        self.last_segment = last_segment
        self.last_item = last_item
        self.exact = exact  # True when the device preserved its counters across the reset


class DeviceFault(LinkError):
    """The device reported an error and stopped (``code`` from messages.ErrorCode)."""

    def __init__(self, message: str, *, code: int, item: int, segment: int, axis: int, value: int):
        super().__init__(message)
        self.code = code
        self.item = item
        self.segment = segment
        self.axis = axis
        self.value = value


class LinkTimeout(LinkError):
    """The device is alive but a requested condition did not happen in time."""


class StepRateError(LinkError, ValueError):
    """A segment over the device's announced step rate (the host checks before sending)."""
