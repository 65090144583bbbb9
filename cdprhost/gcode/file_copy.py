"""The G-code a job prints: a private copy of the file, made once when the job prepares it.

A print reads its file twice (the preflight, then the print) over minutes or hours, and a
print PC's files change under it: a new slice saved over the old one, ``cp`` or ``scp``
writing it again in place. Read twice from the user's path, such a print would move by
lines the preflight never checked, or by the old lines up to some byte and the new ones
after it. Every pass of a job reads its copy instead: what the preflight checked is what
prints, whatever happens to the file meanwhile.

The copy is made in blocks (memory bounded by the block, not the file) and hashed as it
is made (the resume point's key is the bytes printed, not the file's later ones). A file
that changes while it is copied is refused: the copy would be a mix of two versions.
The copy is removed when nothing holds it any more (its owner gone, or the process ending).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import stat
import tempfile
import weakref

from cdprhost.errors import InputError

COPY_BLOCK_BYTES = 1 << 20


def file_stamp(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """What tells a file changed: its size, modification time and inode (None: no file)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns, st.st_ino


class FileCopy:
    """A private copy of ``source`` (the user's file, named in every message): ``path``
    the copy, ``sha256`` and ``size`` of its bytes. Removed when garbage collected."""

    def __init__(self, source: str, path: str, sha256: str, size: int):
        self.source = source
        self.path = path
        self.sha256 = sha256
        self.size = size
        self._remove = weakref.finalize(self, _remove, path)

    def remove(self) -> None:
        """Remove the copy now (idempotent)."""
        self._remove()

    def __repr__(self) -> str:
        return f"FileCopy({self.source!r}, {self.size} bytes)"


def copy_file(
    source: str | os.PathLike[str], folder: str | os.PathLike[str] | None = None
) -> FileCopy:
    """A private copy of ``source`` in ``folder`` (default: the system's temporary folder);
    InputError naming the file when it cannot be read or changed while it was copied."""
    name = os.fspath(source)
    before = file_stamp(name)
    digest = hashlib.sha256()
    size = 0
    try:
        mode = os.stat(name).st_mode
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", source=name) from None
    if not stat.S_ISREG(mode):  # a folder, a pipe, a device: no G-code file to copy
        raise InputError("not a regular file: nothing to print from", source=name)
    try:
        src = open(name, "rb")  # noqa: SIM115 - closed by the with below; open errors named
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", source=name) from None
    try:
        fd, path = tempfile.mkstemp(prefix="cdprhost-print-", suffix=".gcode", dir=folder)
    except OSError as exc:
        src.close()
        where = folder if folder is not None else tempfile.gettempdir()
        raise InputError(
            f"cannot copy it for printing (into {where}): {exc.strerror or exc}", source=name
        ) from None
    try:
        with src, os.fdopen(fd, "wb") as dst:
            while block := src.read(COPY_BLOCK_BYTES):
                digest.update(block)
                dst.write(block)
                size += len(block)
    except OSError as exc:  # a read error, or the copy's folder full
        _remove(path)
        raise InputError(
            f"cannot copy it for printing (into {os.path.dirname(path)}): {exc.strerror or exc}",
            source=name,
        ) from None
    if file_stamp(name) != before or (before is not None and before[0] != size):
        _remove(path)
        raise InputError(
            "the file changed while it was read (still being written?): wait until it is "
            "whole and print it again",
            source=name,
        )
    return FileCopy(name, path, digest.hexdigest(), size)


def _remove(path: str) -> None:
    with contextlib.suppress(OSError):  # already gone (removed by hand, or its folder)
        os.unlink(path)
