"""Wire protocol shared by the host and the (simulated) firmware; see PROTOCOL.md.

- ``crc``, ``varint``: checksums (CRC-32/ISO-HDLC, CRC-8/SMBUS) and compact integers.
- ``framing``: frame layout, ``encode_frame`` and the resynchronising ``Deframer``.
- ``ramp_profile``: a segment's ramp (the time profile its axes share) and the step
  timing on it; ``segments``: the move segment and its vectorised coder;
  ``step_schedule``, ``schedule_block``: the step schedules a segment may carry and
  their wire form; ``messages``: the message table (typed, bounded fields) and its
  codec; ``c_header``: the table as a C header for the firmware.
- ``reliability``, ``endpoint``: go-back-N delivery, adaptive RTO, one link end.
- ``streams``: a deterministic demonstration stream and its expected device record.
- ``device``: the simulated firmware, its fault injector and pseudo-terminal runner.
"""
