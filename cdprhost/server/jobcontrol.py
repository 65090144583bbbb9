"""The one adapter between the server and a print job's stop controls.

Pause, resume, cancel, the e-stop and the server's own shutdown go through here, onto the
job's one safe-stop path (issue 23, :mod:`cdprhost.job.stopping`): a controlled stop within
the motion already sent to the device, a retract, lift and park, heaters as the profile says;
the same path the CLI's signals and the terminal UI use.
"""

from __future__ import annotations

import threading
from typing import Any


def pause(job: Any) -> None:
    job.request_pause()


def resume(job: Any) -> None:
    job.request_resume()


def cancel(job: Any, reason: str = "") -> None:
    """Cancel (a controlled stop, then park); ``reason`` is recorded in the job's end."""
    job.request_cancel(reason)


def emergency_stop(job: Any) -> bool:
    """Stop now, bypassing the queue (heaters off); True when the device acknowledged."""
    return bool(job.emergency_stop())


def shutdown(job: Any, worker: threading.Thread | None, reason: str, timeout_s: float) -> bool:
    """Blocking: cancel with ``reason`` and wait for the job to end (the machine stopped,
    parked, heaters off, resume point saved); after ``timeout_s`` the job e-stops itself.
    True when it ended. The link may be closed only after this returns."""
    ended = bool(job.shutdown(reason, timeout_s=timeout_s))
    if worker is not None:
        worker.join(timeout=5.0)
    return ended
