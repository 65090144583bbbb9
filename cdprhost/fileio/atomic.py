"""Writing a file where the caller said, and only there.

- A regular file (or a path that does not exist yet) is written atomically: a temporary
  file beside it, renamed over it only on success, so it is either complete or as it was.
  A symbolic link is followed: its target is replaced and the link stays a link.
- ``-``, or any path that is the process's standard output (``/dev/stdout``,
  ``/proc/self/fd/1``), is written to ``sys.stdout``, never replaced.
- Any other file that is not a regular file (a FIFO, a terminal, ``/dev/null``), and any
  name of an open file (``/dev/stderr``, ``/dev/fd/N``, ``/proc/...``: one redirected to a
  regular file is appended to, as the shell opened it), is written in place.

New files get the permissions the user's umask gives (``0666 & ~umask``), as ``open``
would, not the private 0600 of a temporary file.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

STALE_S = 600.0  # a temporary file this old was left by a writer that was killed
STDOUT = "-"
# names of a process's open files: whatever they lead to was opened by someone else
_OPEN_FILE_NAMES = ("/proc/", "/dev/fd/", "/dev/stdout", "/dev/stderr", "/dev/stdin")
_umask_lock = threading.Lock()


def remove_stale_temporaries(target: Path, older_than_s: float = STALE_S) -> int:
    """Remove ``target``'s temporary files left behind by killed writers; returns how many."""
    removed = 0
    cutoff = time.time() - older_than_s
    with contextlib.suppress(OSError):
        for tmp in target.parent.glob(f".{target.name}.*.tmp"):
            with contextlib.suppress(OSError):
                if tmp.stat().st_mtime < cutoff:
                    tmp.unlink()
                    removed += 1
    return removed


def current_umask() -> int:
    """The process's umask, read without changing it where the system says it
    (``/proc/self/status``), else by setting and restoring it under a lock."""
    with contextlib.suppress(OSError, ValueError), open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    with _umask_lock:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def new_file_mode() -> int:
    """The mode ``open()`` would give a new file: ``0666`` less the umask."""
    return 0o666 & ~current_umask()


def is_stdout(path: str | os.PathLike[str]) -> bool:
    """``-``, or a path naming the same file as file descriptor 1."""
    if os.fspath(path) == STDOUT:
        return True
    try:
        return os.path.samestat(os.stat(path), os.fstat(1))
    except (OSError, ValueError):
        return False


def is_special(path: str | os.PathLike[str]) -> bool:
    """Written in place, never replaced: stdout, an existing file that is neither a
    regular file nor a folder (FIFO, device, socket), or a name of an open file
    (``/dev/stderr``, ``/dev/fd/N``, anything under ``/proc``)."""
    if is_stdout(path):
        return True
    if os.path.abspath(os.fspath(path)).startswith(_OPEN_FILE_NAMES):
        return True
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


_stdout_stream: list[IO[str]] = []  # set by data_to_stdout: where "-" goes meanwhile


@contextlib.contextmanager
def data_to_stdout(stream: IO[str]) -> Iterator[None]:
    """Within: outputs naming stdout go to ``stream`` even when ``sys.stdout`` is
    redirected (a command whose data goes to stdout sends its messages to stderr)."""
    _stdout_stream.append(stream)
    try:
        yield
    finally:
        _stdout_stream.pop()


@contextlib.contextmanager
def _in_place(path: str | os.PathLike[str], mode: str) -> Iterator[IO[Any]]:
    binary = "b" in mode
    if is_stdout(path):
        stream: Any = _stdout_stream[-1] if _stdout_stream else sys.stdout
        stream.flush()
        out = stream.buffer if binary and hasattr(stream, "buffer") else stream
        yield out
        out.flush()
        return
    regular = False
    with contextlib.suppress(OSError):
        regular = stat.S_ISREG(os.stat(path).st_mode)
    # a regular file behind /dev/stderr or /proc/... is one the shell opened: append to it
    open_mode = ("a" if regular else "w") + ("b" if binary else "")
    text_options: dict[str, Any] = {} if binary else {"encoding": "utf-8", "newline": ""}
    with open(path, open_mode, **text_options) as fh:
        yield fh


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """Open ``path`` for writing as the module says: stdout and special files in place,
    anything else through a temporary file beside the target (a link's target) that is
    renamed over it only on success.

    Temporary files of the same target left by a writer that was killed (older than
    ten minutes) are removed first."""
    if is_special(path):
        with _in_place(path, mode) as fh:
            yield fh
        return
    target = Path(os.path.realpath(path))  # a link stays a link: its target is replaced
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    binary = "b" in mode
    try:
        os.fchmod(fd, new_file_mode())
        text_options: dict[str, Any] = {} if binary else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **text_options, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    with atomic_open(path, "w") as fh:
        fh.write(text)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def output_problem(path: str | os.PathLike[str], *, folder: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (``folder``: made and filled as a folder),
    in a few words, or None when it can. Checked before a command does its work."""
    text = os.fspath(path)
    if text == "":
        return "an empty path"
    if is_stdout(text) or (not folder and is_special(text)):
        if folder:
            return "is not a folder (standard output cannot hold files)"
        if text != STDOUT and not os.access(text, os.W_OK):
            return "is not writable"
        return None
    p = Path(os.path.realpath(text))
    if folder:
        if p.exists() and not p.is_dir():
            return "exists and is not a folder"
        if p.is_dir():
            return None if os.access(p, os.W_OK | os.X_OK) else "the folder is not writable"
    elif p.is_dir():
        return "is a folder (a file is needed here)"
    parent = p.parent
    while not parent.exists():  # the folders that would be made
        parent = parent.parent
    if not parent.is_dir():
        return f"{parent} is not a folder"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"cannot write in {parent} (permission denied)"
    return None
