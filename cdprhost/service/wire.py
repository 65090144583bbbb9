"""The printer service's wire: one JSON object a line over a local stream socket.

A client opens with ``hello`` (the wire version and the service's key), then sends
commands; the service answers ``welcome`` and from then on sends the job's events, the
replies to commands and the job's result. Every message a peer sends is validated here
(pydantic) before anything acts on it: a malformed line is refused with the reason, and a
client that sends one is dropped. Version 1:

client -> service  ``hello`` ``start`` ``pause`` ``resume`` ``cancel`` ``estop`` ``bye``
service -> client  ``welcome`` ``event`` ``reply`` ``result`` ``log``

Job events are the dataclasses of :mod:`cdprhost.job.state`, written as their fields plus
``type`` (the class name), so every client folds them with the one reducer.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from cdprhost.job.state import (
    Event,
    Failure,
    JobState,
    LinkHealth,
    Notice,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
)

VERSION = 1
#: the longest line either side accepts (a start request with its profile is about 10 kB)
MAX_LINE = 1 << 20


class WireError(ValueError):
    """A line that is not a valid message of this wire version."""


class _Msg(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# ------------------------------------------------------------ client -> service


class Hello(_Msg):
    op: Literal["hello"] = "hello"
    v: int
    key: str = Field(max_length=256)
    client: str = Field(default="", max_length=64)  # who: "print", "tui", "server"
    replay: bool = True  # first the current job's events so far (False: a new job follows)


class StartJob(_Msg):
    """Everything a print needs, resolved by the client (absolute paths, the loaded
    profile): the service never reads the client's working folder or options."""

    gcode: str = Field(min_length=1, max_length=4096)
    profile: dict[str, Any]  # a MachineProfile as JSON; validated by the service
    port: str | None = Field(default=None, max_length=4096)  # None: the embedded device
    baud: int | None = Field(default=None, gt=0, le=10_000_000)
    speedup: float | None = Field(default=None, ge=0.0, le=100_000.0)
    sim_faults: str | None = Field(default=None, max_length=4096)
    setup: dict[str, Any] = Field(default_factory=dict)  # Setup.to_json()
    resume: bool = False  # continue at the file's saved resume point
    resume_from_layer: int | None = Field(default=None, ge=0)  # 0-based
    log_path: str = Field(min_length=1, max_length=4096)
    job_log_file: bool = True  # also the .log beside the JSON-lines log
    # where the board's announced limits are recorded (a real board: a profile name or path)
    profile_ref: str | None = Field(default=None, max_length=4096)
    # (the upload server) who started it, for every front end; False: a device fault refuses
    started_by: str = Field(default="", max_length=200)
    clear_fault: bool = True


class Start(_Msg):
    op: Literal["start"] = "start"
    id: int = 0
    job: StartJob


class Pause(_Msg):
    op: Literal["pause"] = "pause"
    id: int = 0


class Resume(_Msg):
    op: Literal["resume"] = "resume"
    id: int = 0


class Cancel(_Msg):
    op: Literal["cancel"] = "cancel"
    id: int = 0
    reason: str = Field(default="", max_length=200)


class Estop(_Msg):
    op: Literal["estop"] = "estop"
    id: int = 0


class Bye(_Msg):
    op: Literal["bye"] = "bye"


Request = Annotated[
    Hello | Start | Pause | Resume | Cancel | Estop | Bye, Field(discriminator="op")
]

# ------------------------------------------------------------ service -> client


class Welcome(_Msg):
    msg: Literal["welcome"] = "welcome"
    v: int
    pid: int
    name: str
    port: str | None = None  # the device this service owns (None: embedded, private)
    job: str = "none"  # the current or last job's state ("none": no job yet)


class EventMsg(_Msg):
    msg: Literal["event"] = "event"
    event: dict[str, Any]


class Reply(_Msg):
    msg: Literal["reply"] = "reply"
    id: int = 0
    ok: bool
    error: str = ""


class ResultMsg(_Msg):
    """The job's end: ``result`` (PrintResult fields) or ``error`` (the job itself broke)."""

    msg: Literal["result"] = "result"
    result: dict[str, Any] | None = None
    error: str = ""


class LogMsg(_Msg):
    msg: Literal["log"] = "log"
    level: str
    text: str


Reply_ = Annotated[Welcome | EventMsg | Reply | ResultMsg | LogMsg, Field(discriminator="msg")]

_REQUEST: TypeAdapter[Any] = TypeAdapter(Request)
_SERVICE: TypeAdapter[Any] = TypeAdapter(Reply_)


def encode(message: BaseModel) -> bytes:
    return message.model_dump_json().encode() + b"\n"


def _decode(adapter: TypeAdapter[Any], line: bytes, tag: str) -> Any:
    if len(line) > MAX_LINE:
        raise WireError(f"a line of {len(line)} bytes (at most {MAX_LINE})")
    try:
        return adapter.validate_json(line)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        where = where or (tag if first["type"].startswith("union_tag") else "message")
        raise WireError(f"{where}: {first['msg']}") from None


def decode_request(line: bytes) -> Any:
    """A client's message, or WireError naming the field and the reason."""
    return _decode(_REQUEST, line, "op")


def decode_reply(line: bytes) -> Any:
    """A service's message, or WireError naming the field and the reason."""
    return _decode(_SERVICE, line, "msg")


# ------------------------------------------------------------ job events

EVENT_TYPES: dict[str, type] = {
    cls.__name__: cls
    for cls in (StateChanged, Planned, Progress, Temperatures, LinkHealth, Failure, Notice)
}


def event_to_json(event: Event) -> dict[str, Any]:
    data = dataclasses.asdict(event)
    data["type"] = type(event).__name__
    return data


def _tuples(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


def event_from_json(data: dict[str, Any]) -> Event:
    """The event ``event_to_json`` wrote; WireError for an unknown type or field."""
    fields = dict(data)
    cls = EVENT_TYPES.get(str(fields.pop("type", "")))
    if cls is None:
        raise WireError(f"event.type: unknown event {data.get('type')!r}")
    names = {f.name for f in dataclasses.fields(cls)}
    if not set(fields) <= names:
        raise WireError(f"event: unknown fields {sorted(set(fields) - names)} for {cls.__name__}")
    values = {k: _tuples(v) for k, v in fields.items()}
    if cls is StateChanged:
        try:
            values["state"] = JobState(str(values.get("state")))
        except ValueError:
            raise WireError(f"event.state: unknown state {values.get('state')!r}") from None
    try:
        return cls(**values)  # type: ignore[no-any-return]
    except TypeError as exc:
        raise WireError(f"event: {exc}") from None


# ------------------------------------------------------------ the device while no job runs
# (added for the upload server and its web page; additive: the messages above are unchanged
# and the two unions are extended here, so a peer of the first version still understands
# every message it knew.)
#
# client -> service  ``device``  (e-stop, heaters off, home, jog, a temperature reading)
# service -> client  ``done``    (the reply to ``device``, with what was done or the reason)
#                    ``job``     (the current job's file and who started it: a front end that
#                                 attaches late names the job as the one that started it)


class DeviceSpec(_Msg):
    """The device to act on and the machine it drives (as in :class:`StartJob`)."""

    profile: dict[str, Any]  # a MachineProfile as JSON; validated by the service
    port: str | None = Field(default=None, max_length=4096)  # None: the embedded device
    baud: int | None = Field(default=None, gt=0, le=10_000_000)
    speedup: float | None = Field(default=None, ge=0.0, le=100_000.0)


#: the farthest a jog moves on each axis (mm)
MAX_JOG_MM = 10.0


class Device(_Msg):
    """A command to the device while no job runs (the e-stop also during a job: the job's)."""

    op: Literal["device"] = "device"
    id: int = 0
    action: Literal["estop", "heaters_off", "home", "jog", "temperatures"]
    dx: float = Field(default=0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)
    dy: float = Field(default=0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)
    dz: float = Field(default=0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)
    device: DeviceSpec


class Done(_Msg):
    """The reply to :class:`Device`: ``ok`` with what was done (and a temperature reading,
    the Temperatures event's fields), or the reason nothing was done. A reading also says
    the device's fault, explained ("" when none), and whether the host may clear it."""

    msg: Literal["done"] = "done"
    id: int = 0
    ok: bool
    text: str = ""
    temperatures: dict[str, Any] | None = None
    fault: str = ""
    clearable: bool = True


class JobInfo(_Msg):
    """The current (or last) job: its file, who started it, when (epoch s)."""

    msg: Literal["job"] = "job"
    gcode: str = ""
    started_by: str = ""
    started_at: float | None = None


_REQUESTS: Any = Annotated[typing.get_args(Request)[0] | Device, Field(discriminator="op")]
_MESSAGES: Any = Annotated[typing.get_args(Reply_)[0] | Done | JobInfo, Field(discriminator="msg")]
_REQUEST = TypeAdapter(_REQUESTS)
_SERVICE = TypeAdapter(_MESSAGES)
