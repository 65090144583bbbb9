"""Motion-capture take readers and writers.

``read_take(path, format=None)`` reads OptiTrack Motive CSV, Vicon Nexus CSV,
Qualisys QTM TSV or C3D into a :class:`Take` (positions in mm, NaN for gaps); the
format is detected from the content. ``write_take(path, take, format, **options)``
writes the same formats (see :mod:`.writers`).
"""

from __future__ import annotations

import os

from cdprhost.calibration.mocap.readers.c3d_take import looks_like_c3d, read_c3d
from cdprhost.calibration.mocap.readers.motive import looks_like_motive, read_motive
from cdprhost.calibration.mocap.readers.qualisys import looks_like_qualisys, read_qualisys
from cdprhost.calibration.mocap.readers.take import FORMATS, Take
from cdprhost.calibration.mocap.readers.vicon import looks_like_vicon, read_vicon
from cdprhost.calibration.mocap.readers.writers import EXTENSIONS, write_take
from cdprhost.errors import InputError

__all__ = ["EXTENSIONS", "FORMATS", "Take", "detect_format", "read_take", "write_take"]

_READERS = {
    "motive-csv": read_motive,
    "vicon-csv": read_vicon,
    "qualisys-tsv": read_qualisys,
    "c3d": read_c3d,
}


def detect_format(path: str | os.PathLike[str]) -> str | None:
    """The take format judged from the file's first bytes, or None if unrecognised."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    if looks_like_c3d(head) and b"\x00" in head[:512]:
        return "c3d"
    text = head.decode("utf-8-sig", errors="replace")
    lines = text.splitlines()[:12] or [""]
    if looks_like_motive(lines[0]):
        return "motive-csv"
    if looks_like_qualisys(lines[0]):
        return "qualisys-tsv"
    if looks_like_vicon(lines):
        return "vicon-csv"
    return None


def read_take(path: str | os.PathLike[str], format: str | None = None) -> Take:
    """Read one take. ``format`` None: detect it. A given format that the content
    contradicts is overridden by the detected one (recorded in ``Take.notes``)."""
    if format is not None and format not in FORMATS:
        raise InputError(
            f"unknown take format {format!r} (expected one of {', '.join(FORMATS)})",
            source=str(path),
        )
    detected = detect_format(path)
    if detected is None and format is None:
        raise InputError(
            "unrecognised take format: expected a Motive CSV ('Format Version,...'), a Vicon Nexus CSV "
            "('Trajectories'), a Qualisys TSV ('NO_OF_FRAMES') or a C3D file",
            source=str(path),
        )
    chosen = detected or format or ""
    take = _READERS[chosen](path)
    if format is not None and detected is not None and detected != format:
        note = f"session says {format} but the file is {detected}; read as {detected}"
        take = Take(
            take.marker_names,
            take.positions,
            take.times_s,
            take.source,
            take.format,
            take.notes + (note,),
        )
    return take
