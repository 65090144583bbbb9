"""The printer service's wire: one JSON object a line over a local stream socket.

A client opens with ``hello`` (the wire version and the service's key), then sends
commands; the service answers ``welcome`` and from then on sends the job's events, the
replies to commands and the job's result. Every message a peer sends is validated here
(pydantic) before anything acts on it: a malformed line is refused with the reason, and a
client that sends one is dropped. Version 1:

client -> service  ``hello`` ``start`` ``pause`` ``resume`` ``cancel`` ``estop`` ``bye``
                   ``override`` (M220 / M221 of the running print)
service -> client  ``welcome`` ``event`` ``reply`` ``result`` ``log``

and, added within version 1 (the device session, for a front end that drives the machine
between prints: the TUI; see the section "device session" below):

client -> service  ``connect`` ``disconnect`` ``status`` ``home`` ``move`` ``heaters``
                   ``motors_off`` ``enable`` ``clear_fault`` (``estop`` without a print)
service -> client  ``answer`` ``device`` ``note`` ``job``

and, added within version 1 (the calibration wizard's device, see "calibration" below):

client -> service  ``visit`` ``observe`` ``capture``

Job events are the dataclasses of :mod:`cdprhost.job.state`, written as their fields plus
``type`` (the class name), so every client folds them with the one reducer.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from cdprhost.job.state import (
    Event,
    Failure,
    JobState,
    LinkHealth,
    Notice,
    Overrides,
    Planned,
    Progress,
    StateChanged,
    Temperatures,
)
from cdprhost.motion.override import MAX_PERCENT, MIN_PERCENT

VERSION = 1
#: the longest line either side accepts (a start request with its profile is about 10 kB)
MAX_LINE = 1 << 20


class WireError(ValueError):
    """A line that is not a valid message of this wire version."""


class UnknownMessage(WireError):
    """A service's message of a kind this client does not know (a newer service): skipped."""


class _Msg(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class _Out(BaseModel):
    """A message of the service: a client ignores fields (and, :class:`UnknownMessage`,
    whole messages) a newer service of the same version added."""

    model_config = ConfigDict(extra="ignore", frozen=True)


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
    clear_fault: bool = True  # a device fault is cleared at start (False: refused)
    started_by: str = Field(default="", max_length=200)  # who (the upload server's client)


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


class Override(_Msg):
    """The running print's speed (M220) or flow (M221) override, percent."""

    op: Literal["override"] = "override"
    id: int = 0
    what: Literal["speed", "flow"]
    percent: float = Field(ge=MIN_PERCENT, le=MAX_PERCENT, allow_inf_nan=False)


# ------------------------------------------------------------ client -> service: device session
# The machine between prints, on the link the service holds while a client asked for it.
# Each is answered with an ``answer`` of the same id.


class Connect(_Msg):
    """Hold the service's device open for this client (the service's port, or its embedded
    device at ``speedup``); answered with the device's identity and status."""

    op: Literal["connect"] = "connect"
    id: int = 0
    profile: dict[str, Any]  # a MachineProfile as JSON; validated by the service
    baud: int | None = Field(default=None, gt=0, le=10_000_000)
    speedup: float | None = Field(default=None, ge=0.0, le=100_000.0)


class Disconnect(_Msg):
    op: Literal["disconnect"] = "disconnect"
    id: int = 0


class Status(_Msg):
    op: Literal["status"] = "status"
    id: int = 0


class Home(_Msg):
    op: Literal["home"] = "home"
    id: int = 0


class MoveTo(_Msg):
    """A straight move to ``target`` (machine frame, mm); refused unless homed."""

    op: Literal["move"] = "move"
    id: int = 0
    target: tuple[float, float, float]
    feed_mm_s: float = Field(default=40.0, gt=0.0, le=1000.0)


class Heaters(_Msg):
    """Heater targets (None: as it is; 0: off); ``wait``: until reached."""

    op: Literal["heaters"] = "heaters"
    id: int = 0
    hotend: float | None = Field(default=None, ge=0.0, le=1000.0)
    bed: float | None = Field(default=None, ge=0.0, le=1000.0)
    wait: bool = False


class MotorsOff(_Msg):
    op: Literal["motors_off"] = "motors_off"
    id: int = 0


class Enable(_Msg):
    op: Literal["enable"] = "enable"
    id: int = 0


class ClearFault(_Msg):
    """M999: leave the device's fault state (home again before moving)."""

    op: Literal["clear_fault"] = "clear_fault"
    id: int = 0


# ------------------------------------------------------------ client -> service: calibration
# What the calibration wizard asks of the device (its fitting stays with the client), in the
# device session like the operations above: refused while a print runs or the device is
# faulted. ``observe`` and ``capture`` are the simulated world of the embedded device.

Coordinate = Annotated[float, Field(ge=-1e5, le=1e5, allow_inf_nan=False)]
Point = tuple[Coordinate, Coordinate, Coordinate]


class Visit(_Msg):
    """The wizard's move (``Machine.visit``): through ``points`` (machine frame, mm, in
    order), homing first when needed, then ``settle_s`` at rest; answered with the settled
    status and the device's clock then (``device_time_s``)."""

    op: Literal["visit"] = "visit"
    id: int = 0
    points: tuple[Point, ...] = Field(min_length=1, max_length=64)
    settle_s: float = Field(default=0.5, ge=0.0, le=30.0, allow_inf_nan=False)


class Observe(_Msg):
    """What watches the embedded simulated device (a pty sim-device has its own ``--truth``
    and ``--mocap-dir``): the virtual motion capture of the hidden true machine ``truth`` (a
    profile name or an absolute path) writing a take into ``mocap_dir`` (absolute) at every
    settle, or the simulated camera of the nominal machine taking pictures of ``camera``
    (width, height) pixels (as the Calibrate screen's ``sim:WxH`` allows); neither: nothing
    watches."""

    op: Literal["observe"] = "observe"
    id: int = 0
    truth: str | None = Field(default=None, min_length=1, max_length=4096)
    mocap_dir: str | None = Field(default=None, min_length=1, max_length=4096)
    camera: (
        tuple[Annotated[int, Field(ge=320, le=3840)], Annotated[int, Field(ge=240, le=2160)]] | None
    ) = None


class Capture(_Msg):
    """The simulated camera's pictures now, each written as a PNG file into ``folder`` (an
    absolute path); answered with the files (``files``), the client's to read and remove."""

    op: Literal["capture"] = "capture"
    id: int = 0
    folder: str = Field(min_length=1, max_length=4096)
    frames: int = Field(default=1, ge=1, le=16)


DeviceRequest = (
    Connect
    | Disconnect
    | Status
    | Home
    | MoveTo
    | Heaters
    | MotorsOff
    | Enable
    | ClearFault
    | Visit
    | Observe
    | Capture
)

Request = Annotated[
    Hello | Start | Pause | Resume | Cancel | Estop | Bye | Override | DeviceRequest,
    Field(discriminator="op"),
]

# ------------------------------------------------------------ service -> client


class Welcome(_Out):
    msg: Literal["welcome"] = "welcome"
    v: int
    pid: int
    name: str
    port: str | None = None  # the device this service owns (None: the embedded one)
    job: str = "none"  # the current or last job's state ("none": no job yet)


class EventMsg(_Out):
    msg: Literal["event"] = "event"
    event: dict[str, Any]


class Reply(_Out):
    msg: Literal["reply"] = "reply"
    id: int = 0
    ok: bool
    error: str = ""


class ResultMsg(_Out):
    """The job's end: ``result`` (PrintResult fields) or ``error`` (the job itself broke)."""

    msg: Literal["result"] = "result"
    result: dict[str, Any] | None = None
    error: str = ""


class LogMsg(_Out):
    msg: Literal["log"] = "log"
    level: str
    text: str


# ------------------------------------------------------------ service -> client: device session


class DeviceState(_Out):
    """The device's status report as a front end shows it (steps, temperatures, drivers,
    homing, and its fault in words)."""

    steps: tuple[int, int, int, int]
    hotend_c: float
    bed_c: float
    hotend_target_c: float
    bed_target_c: float
    enabled_mask: int
    homed_mask: int
    queue_free: int
    fault: str = ""  # "" when not faulted
    clearable: bool = True  # a host may clear the fault (a thermal one: no)


class Health(_Out):
    retransmits: int = 0
    bad_frames: int = 0
    naks: int = 0


class Answer(_Out):
    """The answer to a device-session request (``id``): ``ok`` or ``error``; the device's
    identity (to ``connect``), its status after the operation, an e-stop's confirmation."""

    msg: Literal["answer"] = "answer"
    id: int = 0
    ok: bool
    error: str = ""
    identity: dict[str, Any] | None = None
    status: DeviceState | None = None
    confirmed: bool = False
    device_time_s: float | None = None  # to ``visit``: the device's clock once settled
    files: tuple[str, ...] = ()  # to ``capture``: the pictures written


class DeviceMsg(_Out):
    """To every client holding the device, about once a second between prints: its status
    (None: it did not answer, ``error`` says why) and the link's counters."""

    msg: Literal["device"] = "device"
    connected: bool
    status: DeviceState | None = None
    health: Health | None = None
    error: str = ""


class Note(_Out):
    """What the device said unasked (an error, a reset), or the service about the device."""

    msg: Literal["note"] = "note"
    kind: Literal["device", "error", "notice"] = "device"
    text: str


class JobInfo(_Out):
    """The current (or last) job: its file, its state, who started it and when (wall
    clock, ``time.time()``). Sent to every client when a job starts (before its first
    event) and before a replay."""

    msg: Literal["job"] = "job"
    gcode: str = ""
    state: str = "idle"
    started_by: str = ""
    started_at: float = 0.0


Reply_ = Annotated[
    Welcome | EventMsg | Reply | ResultMsg | LogMsg | Answer | DeviceMsg | Note | JobInfo,
    Field(discriminator="msg"),
]

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
        if tag == "msg" and first["type"] == "union_tag_invalid":
            raise UnknownMessage(f"msg: unknown message {first.get('input')!r}") from None
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
EVENT_TYPES[Overrides.__name__] = Overrides


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
