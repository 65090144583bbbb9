"""The one adapter between the server and a print job's stop controls.

Pause, resume, cancel and the server's own shutdown go through here, so they all use the
job's safe-stop path (issue 23: a controlled stop within the motion already sent, retract,
lift and park; heaters as the profile says). With a job that has ``shutdown`` (the
safe-stop API) it is used as is; with an older job the same is done with its requests.
"""

from __future__ import annotations

import inspect
import threading
from typing import Any


def pause(job: Any) -> None:
    job.request_pause()


def resume(job: Any) -> None:
    job.request_resume()


def cancel(job: Any, reason: str = "") -> None:
    """Cancel (a controlled stop, then park); ``reason`` is recorded when the job takes one."""
    request = job.request_cancel
    if reason and "reason" in inspect.signature(request).parameters:
        request(reason=reason)
    else:
        request()


def shutdown(job: Any, worker: threading.Thread | None, reason: str, timeout_s: float) -> bool:
    """Blocking: cancel with ``reason`` and wait for the job to end (the machine stopped,
    parked, heaters off, resume point saved); True when it ended within ``timeout_s`` (after
    that the job's own shutdown e-stops). The link may be closed only after this returns."""
    if hasattr(job, "shutdown"):
        ended = bool(job.shutdown(reason, timeout_s=timeout_s))
        if worker is not None:
            worker.join(timeout=5.0)
        return ended
    cancel(job, reason)
    if worker is None:
        return True
    worker.join(timeout=timeout_s)
    if worker.is_alive() and hasattr(job, "emergency_stop"):
        job.emergency_stop()
        worker.join(timeout=2.0)
    return not worker.is_alive()
