"""The host link's tuning: frame and window sizes, clock sync, retransmission timing,
the heater lease."""

from __future__ import annotations

SLICE_S = 0.02
MIN_PAYLOAD = 24
START_PAYLOAD = 32  # frames start small and grow while the line is clean
# The payload floor follows the line's measured loss: frames as long as a frame is lost with
# about this probability. A device checks one frame a main-loop turn and answers each with
# an ACK, so short frames cost it time per segment: with 24-byte payloads on a line that
# loses 0.2 % of its bytes the AVR took about one frame (5 segments) every 5 ms, no more
# than it executed at 1000 segments/s, and never caught up after a loss. A heavily damaged
# line (1 % + 1 %) still gets the short frames that get through.
FRAME_LOSS_SHARE = 0.22
# ... and frames grow on clean acknowledgements only up to a length lost about this often
# (on a noisy line, frames grown long while small status frames went through cleanly
# were never again shortened: a frame once sent keeps its size, and a window of 95-byte
# frames at 1 % + 1 % went back and forth for seconds)
FRAME_LOSS_CEILING = 0.5
LOSS_PRIOR_BYTES = 2500  # the estimate starts as 0.5 losses in this many bytes
LOSS_MEMORY_BYTES = 20000  # past this the counts are halved: the estimate follows the line
MAX_WINDOW = 127
START_WINDOW = 8
MIN_WINDOW = 8
CLOCK_SYNC_S = 0.06  # clock samples this far apart before streaming
# The handshake on a noisy line: a HELLO and its IDENT both get through only about one
# time in three at 1 % corruption + 1 % drop per byte, so HELLO is resent, first after
# HELLO_FIRST_S, then each time HELLO_BACKOFF times later (up to an eighth of the link
# timeout), for as long as the line answers anything and at most HANDSHAKE_S (HostLink's
# ``handshake_s``); a line silent for the link timeout ends it at once.
HELLO_FIRST_S = 0.05
HELLO_BACKOFF = 1.5
HANDSHAKE_S = 30.0
STATUS_TIMEOUTS = 3  # a status reply may take this many link timeouts on a lossy line
# The retransmission timeout never goes below this, and doubles on consecutive timeouts
# (back to 1x on the next acknowledgement), as Klipper's host does: a device whose main
# loop is busy, or whose receive ring is full, must not be stormed by go-back-N
# resends on a real UART (PROTOCOL.md section 2). The estimator (SRTT + 4 RTTVAR, wire
# time included) raises it above the measured round trip.
RTO_FLOOR_S = 0.025
RTO_MAX_BACKOFF = 8
# When acknowledgements prove the path faster than the configured baud (a pty, native
# USB: no slow UART behind it), the same 25 ms floor and doubling, but the timeout backs
# off only while the device is silent (no byte for 150 ms), and resends only the oldest
# frame while nothing came since it left (firmware_protocol.reliability): on a noisy
# path a timeout while the device is heard is a frame or an ACK lost to noise, and
# waiting longer would stall the stream. (It was 3 ms without backoff: a clean pty under
# load retransmitted on every scheduling hiccup, and a frozen device drew a window's worth
# of resends every 3 ms, 139 in 1.5 s.)
RTO_FAST = (RTO_FLOOR_S, RTO_MAX_BACKOFF)
# ... while that path has shown no damaged byte and no NAK, the floor is this instead (at
# most a quarter of the link timeout): a pty or USB loses nothing, and there a timeout is
# only a scheduling delay of the device process or the host under load (a clean 1x print on
# a loaded machine timed out at 28 ms; with a 150 ms floor, the cup at 1x on a machine at
# load 4-8 still resent twice, each after the device had been silent 221 and 400 ms); it
# still doubles on a silent device.
CLEAN_RTO_FLOOR_S = 0.5
# ... and longer while the device holds motion: a frame in flight is resent only once the
# device would be left with this much (seconds) of motion (up to CLEAN_RTO_FLOOR_MAX_S
# after the frame left): waiting costs nothing on a path that loses nothing.
CLEAN_DRY_MARGIN_S = 0.25
# ... and on that clean path every timeout doubles the floor for the rest of the session (up
# to this, and to half the link timeout), the ceiling rising with it, and a device report
# that does not acknowledge a frame yet resends nothing (STALE_REPORT_S is for a lossy line):
# a path that loses nothing only ever answers late (a device process or this host
# descheduled on a loaded machine), and each such resend was a spurious retransmission
# (a clean pty under load at 1x: 12 in a print, 129 in 4000 segments with 100 ms of jitter).
CLEAN_RTO_FLOOR_MAX_S = 1.0
# Every DATA frame is sent twice back to back once the measured loss rate loses more than
# this share of frames of the current length (a 1 % + 1 % line: about half of 35-byte
# frames), until it loses less than a third of it: the copy makes good most losses at
# once, where go-back-N would need a round (a NAK or a timeout).
COPY_LOSS = 0.25
# A device report (an ACK with FLOW) that still does not acknowledge the oldest frame this
# long after it left the wire, and after the last acknowledgement that released frames,
# shows it lost with nothing behind it (a gap would have drawn a NAK): it is resent then,
# instead of at its timeout (a frame already resent: after twice this). Longer than a
# main-loop turn of the AVR (up to about 15 ms: a report sent at the end of a turn that
# began before the frame had arrived does not acknowledge it yet).
STALE_REPORT_S = 0.02
# Heater lease of a 2.1 device (PROTOCOL.md 3.3): renewed every quarter of it by the calls
# of the code that drives the machine, never by the keep-alive thread.
HEATER_LEASE_S = 10.0
