"""OctoPrint's reply shapes, built from the printer's status (pure functions).

Only what slicers and phone apps read: ``/api/version``, ``/api/job``, ``/api/printer``,
``/api/settings``, the upload reply and the file listing, with OctoPrint's field names and types. Times in ``/api/job`` are seconds:
``printTime`` is wall time since the start, ``printTimeLeft`` the planned machine time still
to run (``printTimeLeftOrigin``: ``estimate``), ``completion`` a percentage, ``filepos`` the
byte offset of the G-code line the device is executing.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

from cdprhost import __version__
from cdprhost.job.state import JobState, Temperatures
from cdprhost.server.printer import PrinterStatus
from cdprhost.server.uploads import Entry

API_VERSION = "0.1"
SERVER_VERSION = "1.10.0"  # the OctoPrint API level answered (the subset slicers use)

STATE_TEXT = {
    JobState.IDLE: "Operational",
    JobState.PREFLIGHT: "Starting",
    JobState.REFUSED: "Operational",
    JobState.HEATING: "Printing",
    JobState.PRINTING: "Printing",
    JobState.PAUSING: "Pausing",
    JobState.PAUSED: "Paused",
    JobState.CANCELLING: "Cancelling",
    JobState.CANCELLED: "Operational",
    JobState.FAILED: "Error",
    JobState.DONE: "Operational",
}


def version() -> dict[str, str]:
    return {
        "api": API_VERSION,
        "server": SERVER_VERSION,
        "text": f"OctoPrint {SERVER_VERSION} (cdprhost {__version__})",
    }


def state_text(status: PrinterStatus) -> str:
    if not status.connected and not status.busy:
        return "Offline"
    return STATE_TEXT[status.job.state]


def file_info(path: Path | None, relative: str | None) -> dict[str, Any]:
    if path is None:
        return {"name": None, "path": None, "origin": None, "size": None, "date": None}
    try:
        st = path.stat()
        size, date = st.st_size, int(st.st_mtime)
    except OSError:
        size, date = None, None
    return {
        "name": path.name,
        "path": relative or path.name,
        "display": path.name,
        "origin": "local",
        "size": size,
        "date": date,
    }


def elapsed_s(status: PrinterStatus, now: float) -> int | None:
    """Whole seconds the job has run (to its end once it ended); None without a job."""
    if status.file is None or status.started_at is None:
        return None
    end = status.ended_at if status.job.state.finished and status.ended_at else now
    return round(max(0.0, end - status.started_at))


def job(
    status: PrinterStatus,
    relative: str | None,
    now: float | None = None,
    filepos: int | None = None,
) -> dict[str, Any]:
    snap = status.job
    now = time.time() if now is None else now
    has_job = status.file is not None
    print_time = elapsed_s(status, now)
    completion = None
    if has_job:
        completion = round(100.0 * snap.fraction, 2) if snap.state is not JobState.DONE else 100.0
    left = snap.eta_s if has_job and snap.state.active else None
    reply: dict[str, Any] = {
        "job": {
            "file": file_info(status.file, relative),
            "estimatedPrintTime": round(snap.estimated_time_s, 1) if has_job else None,
            "filament": {"tool0": {"length": round(snap.filament_mm, 1), "volume": None}}
            if has_job
            else None,
            "lastPrintTime": None,
            "user": status.started_by or None,
        },
        "progress": {
            "completion": completion,
            "filepos": filepos if has_job else None,
            "printTime": print_time,
            "printTimeLeft": round(left) if left is not None else None,
            "printTimeLeftOrigin": "estimate" if left is not None else None,
        },
        "state": state_text(status),
    }
    if snap.state in (JobState.FAILED, JobState.REFUSED) and snap.reason:
        reply["error"] = snap.reason
    return reply


def refs(base_url: str, relative: str) -> dict[str, str]:
    """The file's URL, its path percent-encoded (UTF-8): ASCII, so it can be a header."""
    return {"resource": f"{base_url}/api/files/local/{quote(relative, safe='/')}"}


def entry(e: Entry, base_url: str) -> dict[str, Any]:
    return {
        "name": e.name,
        "path": e.path,
        "display": e.name,
        "type": "machinecode",
        "typePath": ["machinecode", "gcode"],
        "origin": "local",
        "size": e.size,
        "date": e.date,
        "refs": refs(base_url, e.path),
    }


def uploaded(name: str, relative: str, base_url: str, select: bool, start: bool) -> dict[str, Any]:
    return {
        "files": {
            "local": {
                "name": name,
                "path": relative,
                "display": name,
                "origin": "local",
                "refs": refs(base_url, relative),
            }
        },
        "done": True,
        "effectiveSelect": select,
        "effectivePrint": start,
    }


def state_flags(status: PrinterStatus) -> dict[str, bool]:
    """OctoPrint's ``state.flags`` (``/api/printer``)."""
    s = status.job.state
    operational = status.connected or status.busy
    printing = s in (JobState.HEATING, JobState.PRINTING)
    error = s is JobState.FAILED
    return {
        "operational": operational,
        "printing": printing,
        "paused": s is JobState.PAUSED,
        "pausing": s is JobState.PAUSING,
        "cancelling": s is JobState.CANCELLING,
        "resuming": False,
        "finishing": False,
        "sdReady": False,
        "error": error,
        "ready": operational and not status.busy,
        "closedOrError": not operational or error,
    }


def _reading(actual: float, target: float) -> dict[str, float]:
    return {"actual": round(actual, 2), "target": round(target, 2), "offset": 0}


def printer(
    status: PrinterStatus,
    temps: Temperatures | None,
    exclude: frozenset[str] = frozenset(),
    history: int | None = None,
    now: float | None = None,
) -> dict[str, Any]:
    """``GET /api/printer``: the state and the heaters (``tool0`` and ``bed``), without the
    parts named in ``exclude``; ``history``: that many newest samples of the running job's
    temperature history (``time`` in epoch seconds, spaced as the device reported them)."""
    reply: dict[str, Any] = {}
    if "temperature" not in exclude:
        temperature: dict[str, Any] = {}
        if temps is not None:
            temperature["tool0"] = _reading(temps.hotend, temps.hotend_target)
            temperature["bed"] = _reading(temps.bed, temps.bed_target)
        if history is not None:
            samples = status.job.temperature_history[-history:] if history > 0 else ()
            now = time.time() if now is None else now
            last = samples[-1][0] if samples else 0.0
            target_h = temps.hotend_target if temps else 0.0
            target_b = temps.bed_target if temps else 0.0
            temperature["history"] = [
                {
                    "time": int(now - (last - t)),
                    "tool0": {"actual": round(h, 2), "target": target_h},
                    "bed": {"actual": round(b, 2), "target": target_b},
                }
                for t, h, b in samples
            ]
        reply["temperature"] = temperature
    if "sd" not in exclude:
        reply["sd"] = {"ready": False}
    if "state" not in exclude:
        reply["state"] = {"text": state_text(status), "flags": state_flags(status)}
    return reply


def settings(hotend_c: float = 210.0, bed_c: float = 60.0) -> dict[str, Any]:
    """``GET /api/settings``: the fields slicers (Cura's OctoPrint plugin) and phone apps
    read; everything else OctoPrint would list is left out. No camera is served here."""
    return {
        "api": {"allowCrossOrigin": False},
        "appearance": {"name": "cdprhost", "color": "default", "colorTransparent": False},
        "feature": {
            "sdSupport": False,
            "temperatureGraph": True,
            "gcodeViewer": False,
            "keyboardControl": False,
            "pollWatched": False,
            "modelSizeDetection": False,
        },
        "folder": {"uploads": None, "timelapse": None, "watched": None},
        "printer": {"defaultExtrusionLength": 5},
        "serial": {"autoconnect": True, "disconnectOnErrors": True},
        "temperature": {
            "cutoff": 30,
            "profiles": [{"name": "profile", "extruder": hotend_c, "bed": bed_c}],
            "sendAutomatically": False,
        },
        "webcam": {
            "webcamEnabled": False,
            "timelapseEnabled": False,
            "streamUrl": "",
            "snapshotUrl": "",
            "flipH": False,
            "flipV": False,
            "rotate90": False,
        },
        "plugins": {},
    }
