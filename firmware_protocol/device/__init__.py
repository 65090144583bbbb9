"""The simulated firmware: move queue, step timing, heaters, endstops, faults.

- :class:`~firmware_protocol.device.firmware.SimDevice`: the device model, driven
  by bytes and a link-time clock (no threads, no I/O): checks every field, keeps the
  host watchdog, reports flow by count and time.
- :mod:`~firmware_protocol.device.machine`: the move queue (sized in time), the start
  rule, execution, endstops, heaters; :mod:`~firmware_protocol.device.record`: the
  record of executed segments (compact, streamed to its file).
- :class:`~firmware_protocol.device.harness.VirtualBench`: a SimDevice and two
  fault-injecting byte channels on a shared virtual (or paced) clock, in process.
- :mod:`~firmware_protocol.device.pty_server`: the same device on a pseudo-terminal.
"""
