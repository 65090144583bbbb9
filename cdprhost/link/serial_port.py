"""A pyserial port as a byte transport: opened exclusively, every failure named.

``open_serial(port, baud)`` accepts a device path or any pyserial URL
(``loop://``, ``socket://host:port``, ``rfc2217://...``). Errors: PortNotFound,
PortBusy (another process holds it), PortVanished (unplugged, EIO), LinkError
(permission and everything else).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import select
import time

import serial

from cdprhost.link.errors import LinkError, PortBusy, PortNotFound, PortVanished

log = logging.getLogger(__name__)

READ_SLICE_S = 0.02


def _open_error(port: str, exc: Exception) -> LinkError:
    code = getattr(exc, "errno", None)
    text = str(exc)
    if "exclusively lock" in text or code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK):
        return PortBusy(
            f"{port}: port is in use by another program (close it, or check with `fuser {port}`)"
        )
    if code == errno.ENOENT or "No such file" in text:
        return PortNotFound(f"{port}: no such port (is the device plugged in? try `ls /dev/tty*`)")
    if code == errno.EACCES:
        return LinkError(f"{port}: permission denied (add yourself to the 'dialout' group)")
    return LinkError(f"{port}: cannot open: {text}")


class SerialTransport:
    """Byte transport over an open pyserial port (``write``, ``read``, ``now``, ``close``)."""

    def __init__(self, ser: serial.SerialBase, name: str):
        self._ser = ser
        self.name = name
        # this open raised DTR on a real tty and so reset a board with auto-reset: the
        # handshake then waits for its bootloader (session_setup.BOOTLOADER_WAIT_S)
        self.reset_at_open = False
        fileno = getattr(ser, "fileno", None)
        try:
            self._fd: int | None = fileno() if fileno is not None else None
        except (OSError, ValueError, AttributeError, serial.SerialException):
            self._fd = None

    def now(self) -> float:
        return time.monotonic()

    def write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except serial.SerialTimeoutException:
            raise LinkError(
                f"{self.name}: write timed out (flow control stuck or device not reading)"
            ) from None
        except (serial.SerialException, OSError) as exc:
            raise PortVanished(
                f"{self.name}: port failed on write ({exc}); was it unplugged?"
            ) from None

    def read(self, timeout: float) -> bytes:
        """Bytes available now, or the first ones to arrive within ``timeout`` seconds
        (a real port waits in ``select``: it wakes when bytes arrive, not on a timer)."""
        deadline = time.monotonic() + max(0.0, timeout)
        try:
            if self._fd is not None:
                return self._read_select(self._fd, timeout)
            while True:
                waiting = self._ser.in_waiting
                if waiting:
                    return bytes(self._ser.read(waiting))
                if time.monotonic() >= deadline:
                    return b""
                data = bytes(self._ser.read(1))  # blocks at most READ_SLICE_S
                if data:
                    more = self._ser.in_waiting
                    return data + (bytes(self._ser.read(more)) if more else b"")
        except (serial.SerialException, OSError) as exc:
            raise PortVanished(
                f"{self.name}: port failed on read ({exc}); was it unplugged?"
            ) from None

    def wait_readable(self, timeout: float) -> bool:
        """True when bytes are waiting or arrive within ``timeout`` s, without reading them
        (the link's keep-alive thread waits here without holding the link's lock)."""
        try:
            if self._ser.in_waiting:
                return True
            if self._fd is not None:
                ready, _, _ = select.select([self._fd], [], [], timeout)
                return bool(ready)
        except (serial.SerialException, OSError, ValueError, TypeError):
            pass  # closed or vanished: the next read names it
        time.sleep(min(timeout, READ_SLICE_S))
        return False

    def _read_select(self, fd: int, timeout: float) -> bytes:
        waiting = self._ser.in_waiting
        if not waiting and timeout > 0:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return b""
            waiting = self._ser.in_waiting
            if not waiting:  # readable but empty: pyserial raises if the port hung up
                return bytes(self._ser.read(1))
        return bytes(self._ser.read(waiting)) if waiting else b""

    def close(self) -> None:
        with contextlib.suppress(serial.SerialException, OSError):
            self._ser.close()


def open_serial(port: str, baud: int = 250_000, *, write_timeout_s: float = 2.0) -> SerialTransport:
    """Open ``port`` exclusively (device path or pyserial URL) and drop stale input."""
    try:
        ser = serial.serial_for_url(port, do_not_open=True)
        ser.baudrate = baud
        ser.timeout = READ_SLICE_S
        ser.write_timeout = write_timeout_s
        ser.exclusive = True
        ser.open()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise _open_error(port, exc) from None
    reset = keep_dtr_across_close(ser) and not port.startswith("/dev/pts/")  # a pty: no DTR
    if reset:
        log.warning(
            "%s: opening the port raised DTR, which resets an Arduino Mega (auto-reset): "
            "it restarts through its bootloader (about 1 s); DTR now stays up across closes",
            port,
        )
    with contextlib.suppress(serial.SerialException, OSError):
        ser.reset_input_buffer()
    transport = SerialTransport(ser, port)
    transport.reset_at_open = reset
    return transport


def keep_dtr_across_close(ser: serial.SerialBase) -> bool:
    """Clear the tty's HUPCL so that closing the port leaves DTR asserted: the next open
    then makes no DTR edge and does not reset a board with auto-reset (only the first
    open after plugging it in does). True when HUPCL was set, that is when this open
    raised DTR (the kernel does it before pyserial can stop it) and reset such a board."""
    try:
        import termios

        fd = ser.fileno()
        attrs = termios.tcgetattr(fd)
        if not attrs[2] & termios.HUPCL:
            return False
        attrs[2] &= ~termios.HUPCL
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
        return True
    except (ImportError, AttributeError, OSError, ValueError, serial.SerialException):
        return False  # not a tty (a URL port, another OS): nothing to keep
