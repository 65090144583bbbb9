"""The host link's tuning: frame and window sizes, clock sync, retransmission timing."""

from __future__ import annotations

SLICE_S = 0.02
MIN_PAYLOAD = 24
START_PAYLOAD = 64  # frames start small and grow while the line is clean
MAX_WINDOW = 127
START_WINDOW = 8
MIN_WINDOW = 8
CLOCK_SYNC_S = 0.06  # clock samples this far apart before streaming
STATUS_TIMEOUTS = 3  # a status reply may take this many link timeouts on a lossy line
# The retransmission timeout never goes below this. The estimator (SRTT + 4 RTTVAR, wire
# time included) sets it above the measured round trip; the floor only matters on a fast
# line (a pty, USB) where the round trip is ~1 ms: there, on a noisy line, most timeouts
# are lost ACKs and each one stalls the stream for the whole timeout. At 1 % corrupt +
# 1 % drop a 10 ms floor spent most of the time waiting (the first layer underran at 20x,
# 0 of 6 trials); 3 ms printed it (3 of 4). A spurious timeout costs one window resent.
RTO_FLOOR_S = 0.003
# No exponential backoff on the host: a timeout is a lost frame or ACK (noise), and a
# longer wait only stretches the stall; a slow device still raises the RTO through the
# estimator (each ACK of a frame sent once is a sample). With 4x backoff the first layer
# at 1 %+1 % and 10x underran 3 of 3 times (strings of lost ACKs: each try fails ~80 %
# at 2 % per byte); without, it printed 3 of 3.
RTO_MAX_BACKOFF = 1
