"""What the web page shows of the printer, as JSON (pure functions of a status).

:func:`view` turns a :class:`~cdprhost.server.printer.PrinterStatus` into the small document
the page draws: the state, progress, layer, ETA, temperatures with a short history, the
nozzle in the G-code frame, and the job's end (its reason and resume file).
:func:`urgent` says when a change must reach the browsers at once (a state change) rather
than at the next throttled update (progress, temperatures). :func:`finished_record` is the
history line of a job that ended.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from cdprhost.job.state import JobSnapshot, JobState, Temperatures
from cdprhost.server.printer import PrinterStatus
from cdprhost.server.shapes import elapsed_s, state_text

#: temperature readings sent with each update (the graph's span; one reading per second or so)
GRAPH_POINTS = 90


def _r(value: float | None, digits: int = 1) -> float | None:
    return None if value is None else round(float(value), digits)


def temperatures(snap: JobSnapshot, idle: Temperatures | None = None) -> dict[str, Any] | None:
    """The job's newest reading; ``idle``: a reading asked of the device with no job running
    (it is newer than the last job's)."""
    t = idle if idle is not None and not snap.state.active else snap.temperatures
    if t is None:
        return None
    return {
        "hotend": _r(t.hotend),
        "bed": _r(t.bed),
        "hotend_target": _r(t.hotend_target),
        "bed_target": _r(t.bed_target),
        "stale": t.stale,
    }


def graph(snap: JobSnapshot, points: int = GRAPH_POINTS) -> list[list[float]]:
    """The last ``points`` readings: [device time s, hotend °C, bed °C]."""
    return [
        [round(t, 1), round(h, 1), round(b, 1)] for t, h, b in snap.temperature_history[-points:]
    ]


def nozzle(snap: JobSnapshot, bed_origin: Sequence[float] | None) -> list[float] | None:
    """The effector's position in the G-code frame (machine frame minus the bed origin)."""
    if snap.position is None:
        return None
    o = tuple(bed_origin) if bed_origin is not None else (0.0, 0.0, 0.0)
    return [round(snap.position[i] - float(o[i]), 2) for i in range(3)]


def view(
    status: PrinterStatus,
    relative: str | None,
    bed_origin: Sequence[float] | None = None,
    now: float | None = None,
    idle_temps: Temperatures | None = None,
) -> dict[str, Any]:
    """The page's document of ``status`` (``relative``: the file's name in the upload folder;
    ``idle_temps``: the device's reading while no job runs)."""
    snap = status.job
    now = time.time() if now is None else now
    has_job = status.file is not None
    elapsed = elapsed_s(status, now)
    failure = snap.failure
    return {
        "state": snap.state.value,
        "text": state_text(status),
        "connected": status.connected,
        "busy": status.busy,
        "file": status.file.name if has_job and status.file else None,
        "path": relative,
        "started_by": status.started_by or None,
        "progress": round(100.0 * snap.fraction, 1) if has_job else None,
        "layer": snap.layer,
        "layers": snap.layers,
        "line": snap.line,
        "eta_s": round(snap.eta_s) if has_job and snap.eta_s is not None else None,
        "elapsed_s": elapsed,
        "temps": temperatures(snap, None if status.busy else idle_temps),
        "graph": graph(snap),
        "nozzle": nozzle(snap, bed_origin),
        "reason": snap.reason or None,
        "failure": None
        if failure is None
        else {
            "reason": failure.reason,
            "last_line": failure.last_line,
            "last_layer": failure.last_layer,
            "resume_file": failure.resume_file,
        },
        "notices": list(snap.notices[-3:]),
    }


def urgent(before: dict[str, Any] | None, after: dict[str, Any]) -> bool:
    """A change the browsers must see at once: the state, the file, the connection."""
    if before is None:
        return True
    return any(before.get(k) != after.get(k) for k in ("state", "file", "connected", "busy"))


def finished_record(doc: dict[str, Any]) -> dict[str, Any] | None:
    """The history line of a job that has ended (None while it runs or when there is none)."""
    if doc.get("file") is None or not JobState(doc["state"]).finished:
        return None
    failure = doc.get("failure") or {}
    return {
        "file": doc["file"],
        "path": doc.get("path"),
        "result": doc["state"],
        "reason": doc.get("reason") or failure.get("reason"),
        "layer": doc.get("layer"),
        "layers": doc.get("layers"),
        "last_line": failure.get("last_line"),
        "resume_file": failure.get("resume_file"),
        "ended_at": round(time.time()),
    }
