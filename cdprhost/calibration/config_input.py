"""Reading a session's files at the boundary: TOML tables, pydantic problems as lines
that name the key, and relative paths kept inside their folder.

Shared by the session, the camera configuration and the command line; imports nothing
from the rest of calibration, so every source can use it.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from pydantic import ValidationError

from cdprhost.errors import InputError


def validation_problems(exc: ValidationError, prefix: str = "") -> list[str]:
    """One line per problem: the key's dotted place (under ``prefix``) and what is wrong."""
    out = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in (prefix, *err["loc"]) if p != "") or "(top level)"
        msg = {"missing": "missing required key", "extra_forbidden": "unknown key"}.get(
            err["type"], err["msg"].removeprefix("Value error, ")
        )
        out.append(f"{loc}: {msg}")
    return out


def read_toml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A TOML file's tables; InputError naming the file when unreadable or not TOML."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=str(path)) from None


def contained_path(root: Path, relative: str) -> Path | str:
    """``relative`` resolved inside ``root``, or the reason it is refused: an absolute path
    (POSIX or Windows), a ``..`` escape, or a link that leads outside. Backslashes (folders
    assembled on Windows) count as separators."""
    text = relative.replace("\\", "/")
    if "\x00" in text:
        return "contains a NUL character"
    if PurePosixPath(text).is_absolute() or PureWindowsPath(relative).anchor:
        return (
            f"{relative!r} is an absolute path: take paths must be relative to the session folder"
        )
    if ".." in PurePosixPath(text).parts:
        return f"{relative!r} leads outside the session folder ('..')"
    base = root.resolve()
    target = (base / text).resolve()
    if not target.is_relative_to(base):
        return f"{relative!r} resolves to {target}, outside the session folder"
    return target
