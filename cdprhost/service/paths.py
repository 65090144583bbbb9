"""Where a printer service listens: one socket per device, in a folder only its user can
enter, beside the key a client must present and the service's pid and log.

The folder is ``$CDPRHOST_RUN`` when set, else ``$XDG_RUNTIME_DIR/cdprhost``, else
``/tmp/cdprhost-<uid>``; it is made with mode 0700 and refused when another user owns it
or others may enter it. A device's files are named by a short digest of the state folder
(``$CDPRHOST_STATE``: separate state, separate services) and the device's real path, so
``/dev/ttyACM0`` and a link to it share one service.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from cdprhost.errors import InputError
from cdprhost.job.resume import state_dir

KEY_BYTES = 16


def run_dir() -> Path:
    explicit = os.environ.get("CDPRHOST_RUN")
    if explicit:
        return Path(explicit)
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime and Path(runtime).is_dir():
        return Path(runtime) / "cdprhost"
    return Path("/tmp") / f"cdprhost-{os.getuid()}"


def private_dir() -> Path:
    """The run folder, made 0700 when missing; InputError when others could use it."""
    path = run_dir()
    with contextlib.suppress(FileExistsError):
        path.mkdir(mode=0o700, parents=True)
    st = path.lstat()
    if not path.is_dir() or path.is_symlink():
        raise InputError("the printer service's folder is not a folder", source=str(path))
    if st.st_uid != os.getuid() or st.st_mode & 0o077:
        raise InputError(
            f"the printer service's folder is open to others (owner {st.st_uid}, mode "
            f"{st.st_mode & 0o777:o}); remove it or make it yours with mode 700",
            source=str(path),
        )
    return path


@dataclass(frozen=True)
class ServiceFiles:
    """The files of one service (``name``: the digest that names them)."""

    folder: Path
    name: str

    @property
    def socket(self) -> Path:
        return self.folder / f"{self.name}.sock"

    @property
    def key(self) -> Path:
        return self.folder / f"{self.name}.key"

    @property
    def lock(self) -> Path:
        return self.folder / f"{self.name}.lock"

    @property
    def pid(self) -> Path:
        return self.folder / f"{self.name}.pid"

    @property
    def log(self) -> Path:
        return self.folder / f"{self.name}.log"

    def read_pid(self) -> int | None:
        try:
            return int(self.pid.read_text().strip())
        except (OSError, ValueError):
            return None


def device_name(port: str) -> str:
    """The service name of the device at ``port`` (its real path when it is a file)."""
    real = os.path.realpath(port) if os.path.exists(port) else port
    state = str(state_dir().resolve())
    return "dev-" + hashlib.sha256(f"{state}\0{real}".encode()).hexdigest()[:16]


#: a Unix socket's path is at most this long (Linux: 108 bytes with its terminating NUL)
MAX_SOCKET_PATH = 107


def embedded_name() -> str:
    """The service name of the embedded simulated device: one per state folder."""
    state = str(state_dir().resolve())
    return "sim-" + hashlib.sha256(state.encode()).hexdigest()[:16]


def files_for_port(port: str | None) -> ServiceFiles:
    """The shared service of ``port``; ``None``: the embedded simulated device's of this
    state folder (a front end started again finds the print another one started)."""
    name = device_name(port) if port is not None else embedded_name()
    files = ServiceFiles(private_dir(), name)
    if len(os.fsencode(files.socket)) > MAX_SOCKET_PATH:
        raise InputError(
            f"the folder is too deep for a socket ({MAX_SOCKET_PATH} bytes at most); "
            "set CDPRHOST_RUN to a shorter one",
            source=str(files.folder),
        )
    return files


def write_key(path: Path) -> str:
    """A new random key in a new file of mode 0600 (replacing an old one)."""
    key = secrets.token_hex(KEY_BYTES)
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        fh.write(key + "\n")
    return key


def read_key(path: Path) -> str:
    """The service's key; InputError when it is missing or others could read it."""
    try:
        st = path.stat()
        text = path.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(
            f"cannot read the printer service's key: {exc}", source=str(path)
        ) from None
    if st.st_mode & 0o077 or st.st_uid != os.getuid():
        raise InputError(
            f"the printer service's key is open to others (mode {st.st_mode & 0o777:o})",
            source=str(path),
        )
    return text


def key_matches(given: str, expected: str) -> bool:
    """Constant-time; an empty key never matches."""
    return bool(given) and bool(expected) and hmac.compare_digest(given, expected)
