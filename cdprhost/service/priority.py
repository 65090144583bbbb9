"""The printer service's place in the scheduler: above its front ends when the system allows.

A print is fed in real time: when the stream stalls for longer than the device's queue
holds, the device runs empty (an underrun) and stops. The service needs little CPU but needs
it on time, so it asks for a lower nice value (a higher priority) than the programs around
it: a busy screen, a slicer or a compile at the usual priority then wait for it, not the
other way round (Linux's scheduler gives a nice -10 thread about nine times the share of a
nice 0 one). Only the super-user, or a user whose ``RLIMIT_NICE`` allows it (``ulimit -e``,
``/etc/security/limits.conf``), may lower a nice value; otherwise the service runs as it
was started and says so. ``$CDPRHOST_SERVICE_NICE`` sets the step (0: leave it).

On Linux a nice value belongs to a thread and new threads inherit their creator's: call
:func:`raise_priority` first thing, before any thread starts.
"""

from __future__ import annotations

import os
import resource

#: how far below its starter's nice value the service asks to run
DEFAULT_STEP = 10
ENV = "CDPRHOST_SERVICE_NICE"
NICE_MIN = -20


def wanted_step() -> int:
    """The step asked for: ``$CDPRHOST_SERVICE_NICE`` when it is a whole number 0-39, else
    :data:`DEFAULT_STEP`."""
    text = os.environ.get(ENV, "").strip()
    if text.isdigit() and int(text) < 40:
        return int(text)
    return DEFAULT_STEP


def lowest_allowed() -> int:
    """The lowest nice value this process may set without privilege (``RLIMIT_NICE``: a
    soft limit L allows 20 - L)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_NICE)
    if soft == resource.RLIM_INFINITY:
        return NICE_MIN
    return max(NICE_MIN, 20 - int(soft))


def raise_priority(step: int | None = None) -> str:
    """Lower this thread's nice value by ``step`` (default :func:`wanted_step`), as far as
    allowed; a sentence for the log saying what it is now and why."""
    step = wanted_step() if step is None else step
    before = os.getpriority(os.PRIO_PROCESS, 0)
    if step <= 0:
        return f"nice {before} (left as started: ${ENV}=0)"
    target = max(NICE_MIN, before - step)
    for value in (target, max(target, lowest_allowed())):
        if value >= before:
            break
        try:
            os.setpriority(os.PRIO_PROCESS, 0, value)
        except PermissionError:
            continue
        return f"nice {value} (started at {before}): a busy machine waits for the print"
    return (
        f"nice {before}: not allowed to run above the front ends (RLIMIT_NICE; run as a user "
        "who may, see `ulimit -e`): a busy machine can starve a print"
    )
