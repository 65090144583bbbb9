"""Finding, reading, validating and writing machine profiles (TOML).

A profile argument is a shipped name (``profiles/<name>.toml`` in this repository),
a name in the user's config folder (``$CDPRHOST_PROFILES`` or
``$XDG_CONFIG_HOME/cdprhost/profiles``, default ``~/.config/cdprhost/profiles``),
or a path to a TOML file.
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path
from typing import Any

import tomli_w
from pydantic import ValidationError

from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.profile.device_record import DeviceRecord, read_sidecar, sidecar_path, write_sidecar
from cdprhost.profile.models import MachineProfile

SHIPPED_DIR = Path(__file__).resolve().parents[2] / "profiles"


def user_profile_dir() -> Path:
    if env := os.environ.get("CDPRHOST_PROFILES"):
        return Path(env)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "cdprhost" / "profiles"


def shipped_names() -> list[str]:
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def resolve_profile_path(ref: str | os.PathLike[str]) -> Path:
    """Name or path -> an existing file, or InputError listing where it looked."""
    text = str(ref)
    path = Path(text).expanduser()
    if path.suffix == ".toml" or os.sep in text or path.exists():
        if path.is_file():
            return path
        raise InputError(f"profile file not found: {path}")
    candidates = [user_profile_dir() / f"{text}.toml", SHIPPED_DIR / f"{text}.toml"]
    for cand in candidates:
        if cand.is_file():
            return cand
    raise InputError(
        f"unknown profile '{text}': not a file, not in {candidates[0].parent}, and not shipped "
        f"(shipped: {', '.join(shipped_names())})"
    )


def _format_errors(exc: ValidationError) -> list[str]:
    problems = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        kind = err["type"]
        if kind == "missing":
            msg = "missing required key"
        elif kind == "extra_forbidden":
            msg = "unknown key"
        elif kind == "finite_number":
            msg = f"must be a finite number, got {err.get('input')!r}"
        else:
            msg = err["msg"].removeprefix("Value error, ")
            if (
                "input" in err
                and kind not in ("value_error", "assertion_error")
                and not isinstance(err["input"], dict)
            ):
                msg += f" (got {err['input']!r})"
        problems.append(f"{loc}: {msg}")
    return problems


def _non_finite(data: Any, path: str = "") -> list[str]:
    """TOML allows nan/inf literals; name every one (pydantic may stop at the first)."""
    if isinstance(data, dict):
        return [
            p for k, v in data.items() for p in _non_finite(v, f"{path}.{k}" if path else str(k))
        ]
    if isinstance(data, list):
        return [p for i, v in enumerate(data) for p in _non_finite(v, f"{path}.{i}")]
    if isinstance(data, float) and not math.isfinite(data):
        return [f"{path}: must be a finite number, got {data!r}"]
    return []


def profile_from_dict(
    data: dict[str, Any], *, source: str = "<profile>", default_name: str = ""
) -> MachineProfile:
    data = dict(data)
    data.setdefault("name", default_name)
    try:
        return MachineProfile.model_validate(data)
    except ValidationError as exc:
        problems = _format_errors(exc)
        extra = [p for p in _non_finite(data) if p not in problems]
        raise InputError("invalid profile", source=source, problems=problems + extra) from None


def load_profile(ref: str | os.PathLike[str]) -> MachineProfile:
    """The profile ``ref`` names, with the board's record from its sidecar when there is
    one (it takes precedence over the profile's own ``[device]`` table)."""
    path = resolve_profile_path(ref)
    profile = _load_file(path)
    record = read_sidecar(device_record_path(path))
    return profile if record is None else profile.model_copy(update={"device": record})


def device_record_path(profile_path: str | os.PathLike[str]) -> Path:
    """Where cdprhost keeps what the board announced for the profile at ``profile_path``
    (a sidecar: the profile itself is never rewritten)."""
    return sidecar_path(Path(profile_path), SHIPPED_DIR, user_profile_dir())


def record_device(profile_ref: str | os.PathLike[str], record: DeviceRecord) -> Path | None:
    """Keep ``record`` (what the board announced) for the profile ``profile_ref``; the path
    written, or None when the sidecar already holds the same limits."""
    path = device_record_path(resolve_profile_path(profile_ref))
    if record.same_limits(read_sidecar(path)):
        return None
    write_sidecar(path, record)
    return path


def _load_file(path: Path) -> MachineProfile:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read profile: {exc.strerror}", source=str(path)) from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", source=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"TOML syntax error: {exc}", source=str(path)) from None
    return profile_from_dict(data, source=str(path), default_name=path.stem)


def profile_to_toml(profile: MachineProfile) -> str:
    data = profile.model_dump(mode="json", exclude_none=True)
    return tomli_w.dumps(_listify(data))


def _listify(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _listify(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_listify(v) for v in obj]
    return obj


def save_profile(profile: MachineProfile, path: str | os.PathLike[str]) -> None:
    write_text_atomic(path, profile_to_toml(profile))
