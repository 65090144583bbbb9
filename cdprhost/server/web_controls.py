"""The machine controls of the web page: e-stop, heaters off, home, a cautious jog.

Requests are checked by :class:`Control` (pydantic) before anything moves. The e-stop during a
print is the job's own (motors kept, heaters as the profile says on a failure: see
:func:`cdprhost.machine.commands.estop_flags`); with no job it is sent on the idle link with
the same flags. Heaters off, home and jog run only while no job runs, on the printer's idle
link (``run_idle``); a jog moves at most ``MAX_JOG_MM`` per axis, slowly, only when homed and
only to a point inside the build volume. A printer that does not offer a control refuses it.

A printer that is a client of the printer service (:class:`~.service_printer.ServicePrinter`,
``device``) has every control done by the service's device session
(:mod:`cdprhost.service.device_session`), the one the terminal UI drives too: the jog's
target is checked here, then again by the session before anything moves.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from cdprhost.machine.commands import estop_flags
from cdprhost.server.printer import Refused

JOG_FEED_MM_S = 10.0
#: the farthest a jog moves on each axis (mm)
MAX_JOG_MM = 10.0


class Control(BaseModel):
    """``POST /api/web/control``."""

    model_config = ConfigDict(extra="forbid")
    action: Literal["estop", "heaters_off", "home", "jog"]
    dx: float = Field(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)
    dy: float = Field(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)
    dz: float = Field(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, allow_inf_nan=False)


def _idle(printer: Any, what: str) -> Any:
    run_idle = getattr(printer, "run_idle", None)
    if run_idle is None:
        raise Refused(f"{what} is not offered here: use the terminal UI")
    return run_idle


def _machine(link: Any, printer: Any) -> Any:
    from cdprhost.machine.operations import Machine

    return Machine(link, printer.profile, printer.model, feed_mm_s=JOG_FEED_MM_S)


def jog_target(
    model: Any, here: np.ndarray, delta: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The point ``delta`` away from ``here`` (machine frame), checked against the workspace
    (build volume, slider travel, cable tensions); Refused outside it."""
    from cdprhost.kinematics.workspace import check_workspace

    target = np.asarray(here, dtype=float).reshape(3) + np.asarray(delta, dtype=float)
    if not np.all(np.isfinite(target)):
        raise Refused("the machine's position is unknown; nothing moved")
    report = check_workspace(target[None, :], model.ik(target[None, :]), model.limits)
    if not bool(report.ok[0]):
        raise Refused(f"the jog would leave the workspace: {report.describe(0, model.limits)}")
    return (float(target[0]), float(target[1]), float(target[2]))


def act(printer: Any, control: Control) -> str:
    """Blocking: do ``control``; what was done, or :class:`Refused` with the reason."""
    device = getattr(printer, "device", None)
    if device is not None:  # the printer service does it (and refuses it during a print)
        return str(device(control.action, control.dx, control.dy, control.dz))
    if control.action == "estop":
        return emergency_stop(printer)
    if printer.status().busy:
        raise Refused(f"a print is running: {control.action.replace('_', ' ')} refused")
    if control.action == "heaters_off":
        _idle(printer, "heaters off")(lambda link: _machine(link, printer).heaters_off())
        return "heaters off"
    if control.action == "home":
        _idle(printer, "home")(lambda link: _machine(link, printer).home())
        return "homed"
    delta = (control.dx, control.dy, control.dz)
    if not any(delta):
        raise Refused("a jog of 0 mm: nothing to do")

    def jog(link: Any) -> None:
        m = _machine(link, printer)
        st = m.status()
        if not m.homed():
            raise Refused("home first: the machine does not know where it is; nothing moved")
        here = m.model.fk(m.model.sliders_from_steps(np.asarray(st.steps[:3]))[None, :])[0]
        m.move_to(jog_target(m.model, here, delta))

    _idle(printer, "jog")(jog)
    return "jogged"


def emergency_stop(printer: Any) -> str:
    """The job's e-stop when a job runs, else one on the idle link; both keep the motors."""
    if printer.status().busy:
        stop = getattr(printer, "emergency_stop", None)
        if stop is None:
            raise Refused("e-stop is not offered here: use the terminal UI")
        if not stop():
            raise Refused("the device did not acknowledge the e-stop")
        return "emergency stop (motors kept)"
    flags = estop_flags(printer.profile)
    ok = _idle(printer, "e-stop")(lambda link: link.emergency_stop(timeout=1.0, flags=flags))
    if not ok:
        raise Refused("the device did not acknowledge the e-stop")
    return "emergency stop (motors kept)"
