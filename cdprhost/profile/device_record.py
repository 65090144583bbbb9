"""The profile's record of the board it drives: the ``[device]`` table, and its sidecar.

A board announces what it can do when the host connects (IDENT's ``max_step_rate``,
CAPS's shortest segment); the host plans for it from then on. Before connecting, the
time estimate of ``check`` and ``print`` needs the same figures, so the profile keeps
them: a ``[device]`` table, written by hand or by cdprhost after a connect.

cdprhost never rewrites a profile: a profile is a hand-written TOML file with comments,
and a shipped one is part of the program. What the board announced goes to a sidecar
file, ``<profile>.device.toml`` with one ``[device]`` table, beside the user's profile
(a profile given by path: beside that file; a shipped profile: in the user's profile
folder). The sidecar, the board's latest word, takes precedence over the profile's
own table; deleting it returns to the profile's.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated

import tomli_w
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic

SIDECAR_SUFFIX = ".device.toml"


class DeviceRecord(BaseModel):
    """What the board announces (IDENT, CAPS), as the profile keeps it."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    max_step_rate: Annotated[int, Field(ge=1, le=10_000_000)] = Field(
        description="steps/s the board issues on any one axis (IDENT max_step_rate)"
    )
    min_segment_s: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)] | None = Field(
        default=None, description="the shortest segment it takes, s (CAPS); none: any"
    )
    total_step_rate: Annotated[int, Field(ge=1, le=40_000_000)] | None = Field(
        default=None,
        description="steps/s its four axes take summed (STEP_BUDGET, protocol 3.3); none: "
        "no budget beyond each axis's",
    )
    firmware: str = Field(default="", description="the firmware that announced it, for people")
    recorded: str = Field(
        default="", description="when cdprhost recorded it (UTC, ISO 8601); empty: by hand"
    )

    def same_limits(self, other: DeviceRecord | None) -> bool:
        """The same planning limits (what was recorded when and by whom aside)."""
        return other is not None and (
            self.max_step_rate,
            self.min_segment_s,
            self.total_step_rate,
        ) == (other.max_step_rate, other.min_segment_s, other.total_step_rate)


def sidecar_path(profile_path: str | Path, shipped_dir: Path, user_dir: Path) -> Path:
    """Where the board's record of the profile at ``profile_path`` lives."""
    path = Path(profile_path)
    folder = user_dir if path.resolve().parent == shipped_dir.resolve() else path.parent
    return folder / f"{path.stem}{SIDECAR_SUFFIX}"


def read_sidecar(path: Path) -> DeviceRecord | None:
    """The record in ``path`` (None: no such file); InputError naming the file and the key
    for a bad one."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", source=str(path)) from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"not a TOML file: {exc}", source=str(path)) from None
    if set(data) != {"device"} or not isinstance(data["device"], dict):
        raise InputError("must hold one [device] table and nothing else", source=str(path))
    try:
        return DeviceRecord.model_validate(data["device"])
    except ValidationError as exc:
        problems = [
            f"device.{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
        ]
        raise InputError("invalid board record", source=str(path), problems=problems) from None


def write_sidecar(path: Path, record: DeviceRecord) -> None:
    """Write ``record`` to ``path`` (atomically; its folder is made when missing)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    body = tomli_w.dumps({"device": record.model_dump(exclude_none=True)})
    head = "# What the board announced when cdprhost connected; see docs/machine-model.md.\n"
    write_text_atomic(path, head + body)
