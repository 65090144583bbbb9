"""The upload folder: names checked before anything is written, uploads staged then moved in.

A name is accepted only when every part of it is a plain file or folder name (letters,
digits and ``_ .,-+()[]@#=~`` and spaces; no ``..``, no leading dot, no separator, no
control character, no NUL). An upload is written to a hidden staging folder inside the
upload folder and moved to its place (one ``rename``) only when it is accepted, so a refused
upload leaves nothing behind, and a half-written file is never seen in the listing.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import stat
from dataclasses import dataclass
from pathlib import Path

from cdprhost.job.resume import state_dir

GCODE_SUFFIXES = (".gcode", ".gco", ".g", ".gc", ".nc")
_PART = re.compile(r"[\w .,()\[\]+@#=~-]+")
MAX_PART = 200
MAX_PART_BYTES = 255  # a file name's limit on ext4, btrfs, xfs, APFS (UTF-8 bytes)
MAX_DEPTH = 8
STAGING = ".incoming"


class BadName(ValueError):
    """A file or folder name the server refuses (400), with the reason."""


class UnsafeStaging(OSError):
    """The staging folder is not a plain folder of ours (a link, a file): nothing is written
    through it (409, the reason said)."""


class NotGcode(ValueError):
    """A file that is not G-code by its suffix (415, as OctoPrint answers)."""


def default_folder() -> Path:
    """``<state>/uploads`` beside the job logs (``$CDPRHOST_STATE`` or ~/.local/state/cdprhost)."""
    return state_dir().parent / "uploads"


def check_part(part: str, what: str) -> str:
    if not part:
        raise BadName(f"{what}: empty name")
    if "\x00" in part:
        raise BadName(f"{what}: NUL character in the name")
    if part in (".", ".."):
        raise BadName(f"{what}: {part!r} would leave the upload folder")
    if "/" in part or "\\" in part:
        raise BadName(f"{what}: {part!r}: a path separator in a name")
    if part.startswith("."):
        raise BadName(f"{what}: {part!r}: names may not start with a dot")
    if len(part) > MAX_PART:
        raise BadName(f"{what}: name longer than {MAX_PART} characters")
    if len(part.encode("utf-8", "surrogatepass")) > MAX_PART_BYTES:
        raise BadName(f"{what}: name longer than {MAX_PART_BYTES} bytes (UTF-8)")
    if not _PART.fullmatch(part) or part != part.strip() or part.endswith("."):
        raise BadName(
            f"{what}: {part!r}: use letters, digits, spaces and _ . , - + ( ) [ ] @ # = ~ only"
        )
    return part


def check_folder(path: str | None) -> tuple[str, ...]:
    """The ``path`` form field: a folder inside the upload folder ('' or '/' is its root;
    a leading '/' means the upload folder's root, as OctoPrint reads it)."""
    text = (path or "").strip()
    if "\x00" in text:
        raise BadName("path: NUL character in the folder")
    if "\\" in text:
        raise BadName(f"path: {text!r}: backslash in the folder")
    parts = tuple(p for p in text.strip("/").split("/") if p) if text.strip("/") else ()
    if len(parts) > MAX_DEPTH:
        raise BadName(f"path: more than {MAX_DEPTH} folders deep")
    if "//" in text.strip("/"):
        raise BadName(f"path: {text!r}: empty folder name")
    return tuple(check_part(p, "path") for p in parts)


def check_filename(name: str | None) -> str:
    """The multipart ``filename``: a plain G-code file name (no folder, nothing absolute)."""
    if name is None or not name.strip():
        raise BadName("file: the upload has no file name")
    if name.startswith(("/", "\\")) or re.match(r"[A-Za-z]:[\\/]", name):
        raise BadName(f"file: {name!r}: an absolute path, not a file name")
    if "/" in name or "\\" in name:
        raise BadName(f"file: {name!r}: a path, not a file name")
    check_part(name, "file")
    if not name.lower().endswith(GCODE_SUFFIXES):
        raise NotGcode(f"file: {name!r}: not G-code (accepted: {', '.join(GCODE_SUFFIXES)})")
    return name


@dataclass(frozen=True)
class Entry:
    name: str
    path: str  # relative to the upload folder, '/'-separated
    size: int
    date: int  # modification time, epoch s


class UploadFolder:
    def __init__(self, root: Path | str | None = None):
        self.root = Path(root) if root is not None else default_folder()

    def ensure(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        self.clean_staging()

    def clean_staging(self) -> None:
        """Drop what an interrupted upload left in the staging folder (a link planted in its
        place is left alone: :meth:`stage` refuses it)."""
        staging = self.root / STAGING
        if not staging.is_symlink():
            shutil.rmtree(staging, ignore_errors=True)

    def target(self, folder: tuple[str, ...], name: str) -> Path:
        path = self.root.joinpath(*folder, name)
        # belt and braces: the checked parts cannot leave the root, and no symlink may either
        real_root = self.root.resolve()
        parent = path.parent.resolve()
        if parent != real_root and real_root not in parent.parents:
            raise BadName(f"{'/'.join((*folder, name))}: outside the upload folder")
        return path

    def relative(self, path: Path) -> str:
        return path.relative_to(self.root).as_posix()

    def stage(self, name: str) -> Path:
        """A fresh path to write an upload to (in a hidden folder of its own, same name)."""
        staging = self.root / STAGING
        with contextlib.suppress(FileExistsError):
            staging.mkdir(mode=0o700)
        _plain_folder(staging)
        folder = staging / secrets.token_hex(8)
        folder.mkdir(mode=0o700)  # no parents: nothing is made through a link
        _plain_folder(folder)
        return folder / name

    def commit(self, staged: Path, target: Path) -> Path:
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staged, target)
        self.discard(staged)
        return target

    def discard(self, staged: Path) -> None:
        if staged.parent.is_symlink() or staged.parent.parent.is_symlink():
            return  # never unlink through a planted link
        with contextlib.suppress(OSError):
            staged.unlink()
        with contextlib.suppress(OSError):
            staged.parent.rmdir()

    def listing(self) -> list[Entry]:
        out: list[Entry] = []
        if not self.root.is_dir():
            return out
        for dirpath, dirnames, filenames in os.walk(self.root):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for f in sorted(filenames):
                if f.startswith(".") or not f.lower().endswith(GCODE_SUFFIXES):
                    continue
                p = Path(dirpath) / f
                with contextlib.suppress(OSError):
                    st = p.stat()
                    out.append(Entry(f, self.relative(p), st.st_size, int(st.st_mtime)))
        return out

    def find(self, relative: str) -> Path | None:
        """An uploaded file by its relative path (checked like an upload), or None."""
        parts = [p for p in relative.strip("/").split("/") if p]
        if not parts:
            return None
        folder = check_folder("/".join(parts[:-1]))
        name = check_filename(parts[-1])
        path = self.target(folder, name)
        return path if path.is_file() else None


def _plain_folder(path: Path) -> None:
    """Raise :class:`UnsafeStaging` unless ``path`` itself (not what it points to) is a folder
    owned by this process's user."""
    st = os.lstat(path)
    if stat.S_ISLNK(st.st_mode):
        raise UnsafeStaging(f"{path} is a link: uploads are never staged through one (remove it)")
    if not stat.S_ISDIR(st.st_mode):
        raise UnsafeStaging(f"{path} is not a folder (remove it)")
    if st.st_uid != os.getuid():
        raise UnsafeStaging(f"{path} belongs to another user (remove it)")
