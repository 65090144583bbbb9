"""The simulated firmware: move queue, step timing, heaters, endstops, faults.

- :class:`~firmware_protocol.device.firmware.SimDevice`: the device model, driven
  by bytes and a link-time clock (no threads, no I/O).
- :class:`~firmware_protocol.device.harness.VirtualBench`: a SimDevice and two
  fault-injecting byte channels on a shared virtual (or paced) clock, in process.
- :mod:`~firmware_protocol.device.pty_server`: the same device on a pseudo-terminal.
"""
