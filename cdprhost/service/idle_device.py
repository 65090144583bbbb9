"""The device while no job runs: the few commands a front end's web page offers (e-stop,
heaters off, home, a cautious jog, a temperature reading), on a small device session.

The session is opened at the first such command and kept (a homed machine stays homed for
the jog that follows); a job that starts closes it first (the job opens the device itself),
and the service closes it when it ends. Every command is checked before anything moves: a
jog only when homed, at most :data:`~cdprhost.service.wire.MAX_JOG_MM` per axis, slowly, and
only to a point inside the workspace.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import threading
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.job.state import temperatures_of
from cdprhost.link import LinkError
from cdprhost.link.errors import DeviceFault
from cdprhost.machine.prepare import describe_fault, fault_clearable
from cdprhost.service import wire
from firmware_protocol.messages import THERMAL_ERRORS

log = logging.getLogger(__name__)

JOG_FEED_MM_S = 10.0


class NotDone(Exception):
    """The command was refused or failed; the message says why (nothing moved)."""


def jog_target(
    model: Any, here: np.ndarray, delta: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The point ``delta`` away from ``here`` (machine frame), checked against the workspace
    (build volume, slider travel, cable tensions); NotDone outside it."""
    from cdprhost.kinematics.workspace import check_workspace

    target = np.asarray(here, dtype=float).reshape(3) + np.asarray(delta, dtype=float)
    if not np.all(np.isfinite(target)):
        raise NotDone("the machine's position is unknown; nothing moved")
    report = check_workspace(target[None, :], model.ik(target[None, :]), model.limits)
    if not bool(report.ok[0]):
        raise NotDone(f"the jog would leave the workspace: {report.describe(0, model.limits)}")
    return (float(target[0]), float(target[1]), float(target[2]))


def open_device(spec: wire.DeviceSpec, profile: Any) -> Any:
    if spec.port:
        from cdprhost.link import open_link

        baud = spec.baud or profile.serial.baud
        return open_link(spec.port, baud=baud, timeout_s=profile.serial.timeout_s)
    from cdprhost.sim.embedded import open_embedded

    return open_embedded(speedup=spec.speedup)


class IdleDevice:
    """The service's device session between jobs (one command at a time)."""

    def __init__(self, opener: Any = open_device):
        self._open = opener
        self._link: Any = None
        self._opened_as: tuple[str | None, int | None, float | None] | None = None
        self._lock = threading.Lock()

    def close(self) -> None:
        with self._lock:
            self._close()

    def take(self, port: str | None, baud: int | None, speedup: float | None) -> Any:
        """The session's link for a job on the same device opened the same way (the
        session ends; the job owns the link now), else None (and the session is closed)."""
        with self._lock:
            link, same = self._link, self._opened_as == (port, baud, speedup)
            if link is not None and same:
                try:
                    link.request_status()
                except DeviceFault:  # alive, stopped by a fault: the job decides
                    pass
                except (LinkError, OSError):  # gone: the job opens the device again
                    self._close()
                    return None
                self._link = None
                return link
            self._close()
            return None

    def _close(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            with contextlib.suppress(Exception):
                link.close()

    def _session(self, spec: wire.DeviceSpec, profile: Any) -> Any:
        """The kept link, checked; opened (again) when there is none or it has failed."""
        link = self._link
        if link is not None:
            try:
                link.request_status(timeout=profile.serial.timeout_s)
                return link
            except DeviceFault:  # alive, stopped by a fault: the command says so
                return link
            except (LinkError, OSError):
                self._close()
        self._link = self._open(spec, profile)
        self._opened_as = (spec.port, spec.baud, spec.speedup)
        return self._link

    def act(self, request: wire.Device, busy: Any = lambda: "") -> wire.Done:
        """Blocking: do ``request`` on the device; the reply (ok, or the reason). ``busy()``:
        why the device is not free now ("" when it is), asked once the session is ours."""
        from cdprhost.profile.models import MachineProfile

        try:
            profile = MachineProfile.model_validate(request.device.profile)
        except ValueError as exc:
            return wire.Done(id=request.id, ok=False, text=f"refused: device.profile: {exc}")
        with self._lock:
            why = busy()
            if why:
                what = request.action.replace("_", " ")
                return wire.Done(id=request.id, ok=False, text=f"{why}: {what} refused")
            try:
                return self._act(request, profile)
            except NotDone as exc:
                return wire.Done(id=request.id, ok=False, text=str(exc))
            except (CdprError, LinkError, OSError) as exc:
                return wire.Done(id=request.id, ok=False, text=f"{exc}; nothing done")

    def _act(self, request: wire.Device, profile: Any) -> wire.Done:
        from cdprhost.machine.commands import estop_flags
        from cdprhost.machine.operations import Machine

        link = self._session(request.device, profile)
        action = request.action
        if action == "temperatures":
            try:
                status = link.request_status(timeout=profile.serial.timeout_s)
            except DeviceFault as exc:  # faulted in this session (an e-stop): no reading
                code = int(exc.code or 0)
                fault = f"the device is stopped by a fault ({exc})"
                return wire.Done(
                    id=request.id,
                    ok=True,
                    text="faulted",
                    fault=fault,
                    clearable=code not in THERMAL_ERRORS,
                )
            reading = dataclasses.asdict(temperatures_of(status))
            return wire.Done(
                id=request.id,
                ok=True,
                text="read",
                temperatures=reading,
                fault=describe_fault(status) or "",
                clearable=fault_clearable(status),
            )
        if action == "estop":
            if not link.emergency_stop(timeout=1.0, flags=estop_flags(profile)):
                raise NotDone("the device did not acknowledge the e-stop")
            return wire.Done(id=request.id, ok=True, text="emergency stop (motors kept)")
        machine = Machine(link, profile, feed_mm_s=JOG_FEED_MM_S)
        if action == "heaters_off":
            machine.heaters_off()
            return wire.Done(id=request.id, ok=True, text="heaters off")
        if action == "home":
            machine.home()
            return wire.Done(id=request.id, ok=True, text="homed")
        delta = (request.dx, request.dy, request.dz)
        if not any(delta):
            raise NotDone("a jog of 0 mm: nothing to do")
        status = machine.status()
        if not machine.homed():
            raise NotDone("home first: the machine does not know where it is; nothing moved")
        model = machine.model
        here = model.fk(model.sliders_from_steps(np.asarray(status.steps[:3]))[None, :])[0]
        machine.move_to(jog_target(model, here, delta))
        return wire.Done(id=request.id, ok=True, text="jogged")
