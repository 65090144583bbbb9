"""The API key the print server requires: made at first use, kept in one file of mode 0600.

The file is ``$XDG_CONFIG_HOME/cdprhost/api-key`` (``~/.config/cdprhost/api-key`` when the
variable is unset). It is created with ``O_EXCL`` and mode 0600 from the start (never
readable by others, not even for an instant), and replaced atomically on rotation. The
check compares in constant time, and an empty key (or an empty stored key) never matches.
"""

from __future__ import annotations

import contextlib
import hmac
import logging
import os
import secrets
from pathlib import Path

from cdprhost.errors import InputError

KEY_BYTES = 16  # 128 bits, written as 32 upper-case hex digits (the form OctoPrint uses)
MIN_KEY_CHARS = 16


def config_dir() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "cdprhost"


def key_path() -> Path:
    return config_dir() / "api-key"


def new_key() -> str:
    return secrets.token_hex(KEY_BYTES).upper()


def _write_new(path: Path, key: str) -> None:
    """Write ``key`` to a new file of mode 0600 beside ``path``, then move it into place."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(key + "\n")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def read_key(path: Path | None = None) -> str | None:
    """The stored key, or None when there is none. A key file others can read, or one that
    holds no usable key, is refused (exit 2) rather than trusted."""
    path = path or key_path()
    try:
        st = path.stat()
        text = path.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the API key: {exc}", source=str(path)) from None
    if st.st_mode & 0o077:
        raise InputError(
            f"the API key file is readable by others (mode {st.st_mode & 0o777:o}); "
            "`cdprhost api-key --rotate` makes a new one with mode 600",
            source=str(path),
        )
    if len(text) < MIN_KEY_CHARS or not text.isprintable() or " " in text:
        raise InputError(
            "the API key file holds no usable key; `cdprhost api-key --rotate` makes one",
            source=str(path),
        )
    return text


def load_or_create(path: Path | None = None) -> tuple[str, bool]:
    """(key, created): the stored key, made first when there is none."""
    path = path or key_path()
    key = read_key(path)
    if key is not None:
        return key, False
    return rotate(path), True


def rotate(path: Path | None = None) -> str:
    """Write a new key (a running server's :class:`KeyFile` refuses the old one at once)."""
    path = path or key_path()
    key = new_key()
    try:
        _write_new(path, key)
    except OSError as exc:
        raise InputError(
            f"cannot write the API key: {exc.strerror or exc}", source=str(path)
        ) from None
    return key


def key_matches(expected: str, given: str | None) -> bool:
    """Constant-time comparison; an empty (or missing) key is no key."""
    if not expected or not given:
        return False
    return hmac.compare_digest(expected.encode("utf-8"), given.encode("utf-8", "replace"))


class KeyFile:
    """The key a running server checks: read again when the file changes, so a
    ``cdprhost api-key --rotate`` takes effect at once (the old key stops working). A key file
    that went missing or became unusable keeps the last good key, logged, never no key."""

    def __init__(self, path: Path | None = None):
        self.path = path or key_path()
        self.key, self.created = load_or_create(self.path)
        self._stamp = self._stat()

    def _stat(self) -> tuple[int, int] | None:
        try:
            st = self.path.stat()
        except OSError:
            return None
        return (st.st_mtime_ns, st.st_ino)

    def current(self) -> str:
        stamp = self._stat()
        if stamp is not None and stamp != self._stamp:
            self._stamp = stamp
            try:
                key = read_key(self.path)
            except InputError as exc:
                logging.getLogger(__name__).warning("API key file: %s (keeping the last key)", exc)
                key = None
            if key:
                self.key = key
        return self.key
