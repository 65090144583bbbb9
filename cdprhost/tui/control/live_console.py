"""Console commands carried out on a connected machine (:mod:`cdprhost.machine`), answered
in lines. Blocking: called from a worker thread."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.machine import Machine, NotHomed
from cdprhost.tui.control.console import HELP, ConsoleCommand, ConsoleError, parse_command
from cdprhost.tui.control.jog import check_jog
from cdprhost.tui.control.views import ConsoleLine, DeviceStatusView, unsigned_zero

HEAT_WAIT_S = 900.0


def _line(kind: str, text: str) -> ConsoleLine:
    return ConsoleLine(kind, text, time.time())


def status_lines(view: DeviceStatusView, bed_origin: Any) -> list[str]:
    """M114/M105 style answers from a status view."""
    out = []
    if view.position is not None:
        g = np.asarray(view.position) - np.asarray(bed_origin, dtype=float)
        out.append(
            "position X{:.2f} Y{:.2f} Z{:.2f} (G-code frame); machine frame ({:.2f}, {:.2f}, "
            "{:.2f}) mm".format(*(unsigned_zero(v, 2) for v in (*g, *view.position)))
        )
    else:
        out.append("position unknown: not homed (G28 homes)")
    if view.steps is not None:
        out.append("steps " + " ".join(f"{a}:{v}" for a, v in zip("ABCE", view.steps)))
    return out


def temperature_line(view: DeviceStatusView) -> str:
    def t(v: float | None) -> str:
        return "--" if v is None else f"{v:.1f}"

    return (
        f"hotend {t(view.hotend)} / {view.hotend_target:.1f} °C   "
        f"bed {t(view.bed)} / {view.bed_target:.1f} °C"
    )


def run_console(
    text: str,
    machine: Machine,
    status_view: Any,
    identity_rows: tuple[tuple[str, str], ...],
    feed_mm_s: float,
) -> list[ConsoleLine]:
    """Carry out one console line; ``status_view`` turns a link status into a view."""
    out = [_line("sent", text.strip())]
    try:
        cmd = parse_command(text)
        out += [
            _line("reply", r) for r in _execute(cmd, machine, status_view, identity_rows, feed_mm_s)
        ]
    except ConsoleError as exc:
        out.append(_line("error", str(exc)))
    except NotHomed:
        out.append(_line("error", "the modules are not homed: G28 first"))
    except (CdprError, OSError) as exc:
        out.append(_line("error", str(exc) or "the device did not answer"))
    return out


def _execute(
    cmd: ConsoleCommand,
    m: Machine,
    status_view: Any,
    identity_rows: tuple[tuple[str, str], ...],
    feed_mm_s: float,
) -> list[str]:
    profile = m.profile
    bed = np.asarray(profile.build_volume.bed_origin, dtype=float)
    match cmd.op:
        case "help":
            return [f"{c:<18} {what}" for c, what in HELP]
        case "speed" | "flow":
            raise ConsoleError(
                f"no print is running: {cmd.text.split()[0].upper()} sets a print's {cmd.op}"
            )
        case "home":
            return ["ok homed", *status_lines(status_view(m.home()), bed)]
        case "enable":
            m.enable()
            return ["ok drivers on"]
        case "motors_off":
            m.motors_off()
            return ["ok drivers off"]
        case "estop":
            answered = m.emergency_stop()
            said = "ok emergency stop" if answered else "emergency stop sent (not confirmed)"
            return [f"{said}: motion, heaters and drivers off; M999 clears the stop"]
        case "clear":
            m.link.clear_fault()
            return ["ok cleared: home (G28) before moving"]
        case "temps":
            return [temperature_line(status_view(m.status()))]
        case "position":
            return status_lines(status_view(m.status()), bed)
        case "identity":
            return [f"{k}: {v}" for k, v in identity_rows]
        case "heaters":
            limits = {"hotend": profile.heaters.hotend_max_c, "bed": profile.heaters.bed_max_c}
            for heater, target in cmd.values.items():
                if not 0 <= target <= limits[heater]:
                    raise ConsoleError(f"{heater} target must be within 0-{limits[heater]:g} °C")
            view = status_view(
                m.set_heaters(cmd.values.get("hotend"), cmd.values.get("bed"), wait=cmd.wait)
            )
            if cmd.wait:
                m.link.wait_idle(HEAT_WAIT_S)
                view = status_view(m.status())
            return ["ok", temperature_line(view)]
        case "move":
            here = status_view(m.ready())  # a faulted device: refused before anything else
            if here.position is None:
                raise NotHomed("not homed")
            target = np.asarray(here.position, dtype=float) - bed
            for k, axis in enumerate("xyz"):
                if axis in cmd.values:
                    target[k] = cmd.values[axis]
            machine_target = tuple(float(v) for v in target + bed)
            check = check_jog(m.model, here.position, machine_target)  # type: ignore[arg-type]
            if not check.ok:
                raise ConsoleError(f"refused, nothing moved: {check.reason}")
            feed = cmd.values.get("f", feed_mm_s * 60.0) / 60.0
            moved = status_view(m.move_to(machine_target, feed_mm_s=feed))  # type: ignore[arg-type]
            return ["ok", *status_lines(moved, bed)]
    raise ConsoleError(f"{cmd.op}: not a console operation")
