"""Wire protocol shared by the host and the (simulated) firmware; see PROTOCOL.md.

- ``crc``, ``varint``: checksums (CRC-32/ISO-HDLC, CRC-8/SMBUS) and compact integers.
- ``framing``: frame layout, ``encode_frame`` and the resynchronising ``Deframer``.
- ``segments``: move-segment semantics (shared ramp profile, step timing) and the
  vectorised segment coder; ``messages``: the message table (typed, bounded fields)
  and its codec; ``c_header``: the table as a C header for the firmware.
- ``reliability``, ``endpoint``: go-back-N delivery, adaptive RTO, one link end.
- ``streams``: a deterministic demonstration stream and its expected device record.
- ``device``: the simulated firmware, its fault injector and pseudo-terminal runner.
"""
