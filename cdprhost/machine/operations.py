"""Operations on a connected machine: the one way to home, enable, heat, move, park and stop.

The print job, the calibration wizard, the CLI and the TUI all drive the device through a
:class:`Machine`. Every move starts from the device's own absolute step counters (read
back first), never from a position the host assumes, and keeps the extruder where it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.errors import CdprError
from cdprhost.kinematics.machine import MachineModel
from cdprhost.link.device_setup import setup_from_profile
from cdprhost.link.errors import LinkError
from cdprhost.link.events import DeviceStatus
from cdprhost.link.host_link import HostLink
from cdprhost.machine.board_limits import board_caps
from cdprhost.machine.commands import enable_all, heater_messages, home_commands, motors_off
from cdprhost.machine.faults import DeviceFaulted, describe_fault, fault_clearable, refusal
from cdprhost.motion.direct import direct_path, state_at_steps
from cdprhost.profile.models import MachineProfile
from firmware_protocol.codes import ErrorCode
from firmware_protocol.segments import SegmentBatch

ALL_MODULES = 0b111
HOMING_TIMEOUT_S = 180.0
COMMAND_TIMEOUT_S = 10.0


class NotHomed(CdprError):
    """A move was asked of modules whose position is unknown."""


def _error_name(code: int) -> str:
    try:
        return f"{ErrorCode(code).name} reported" if code else "it reports a fault"
    except ValueError:
        return f"error code {code} reported"


@dataclass(frozen=True)
class MoveResult:
    """Where a move left the modules (absolute steps) and the device clock when it settled."""

    steps: np.ndarray
    device_time_s: float


def end_exactly(wire: SegmentBatch, reached: ArrayLike, target: ArrayLike) -> SegmentBatch:
    """``wire`` ending at module steps ``target`` instead of ``reached`` (its last segment,
    or one more segment ending at rest when there is none, takes up the few steps)."""
    diff = np.asarray(target, dtype=np.int64)[:3] - np.asarray(reached, dtype=np.int64)[:3]
    if not diff.any():
        return wire
    if len(wire) == 0:  # already there but for a few steps: a short move to rest
        deltas = np.zeros((2, 4), dtype=np.int64)
        half = diff // 2
        deltas[0, :3], deltas[1, :3] = half, diff - half
        ticks = np.full(2, max(int(np.abs(diff).max()) * 20, 20), dtype=np.int64)
        return SegmentBatch(ticks, deltas, np.array([0, 255], dtype=np.int16))
    deltas = wire.deltas.copy()
    deltas[-1, :3] += diff
    return SegmentBatch(wire.ticks, deltas, wire.ramps)


class Machine:
    """A handshaken link plus the machine it drives (profile and kinematic model)."""

    def __init__(
        self,
        link: HostLink,
        profile: MachineProfile,
        model: MachineModel | None = None,
        *,
        feed_mm_s: float = 40.0,
        settle_s: float = 0.0,
    ):
        self.link = link
        self.profile = profile
        self.model = model or MachineModel.from_profile(profile)
        self.feed_mm_s = float(feed_mm_s)
        self.settle_s = float(settle_s)
        link.set_machine(setup_from_profile(profile))  # travel limits, PID gains (2.1)

    # ------------------------------------------------------------------ state
    @property
    def clock_hz(self) -> int:
        identity = self.link.identity
        if identity is None:
            raise CdprError("not connected: the link has no session")
        return int(identity.clock_hz)

    def status(self, timeout_s: float | None = None) -> DeviceStatus:
        """The device's status, asked for now."""
        return self.link.request_status(timeout=timeout_s)

    def homed(self) -> bool:
        return self.status().homed_mask & ALL_MODULES == ALL_MODULES

    def ready(self) -> DeviceStatus:
        """The device's status, asked for now, when it can take a command; a device stopped
        by a fault (an e-stop, its watchdog, an error) discards what it is sent, so every
        operation asks here first and is refused (:class:`DeviceFaulted`, nothing sent) with
        the fault and the way out. A lost link raises its own error."""
        st = self.status()
        fault = describe_fault(st)
        link_fault = getattr(self.link, "fault", None)  # this session's, if the report lags
        if fault is None and link_fault is not None:
            fault = f"the device is stopped by a fault ({link_fault})"
        if fault is not None:
            raise DeviceFaulted(refusal(fault, fault_clearable(st)))
        return st

    # ---------------------------------------------------------------- drivers
    def enable(self) -> DeviceStatus:
        self.ready()
        self.link.send(enable_all())
        self.link.wait_idle(COMMAND_TIMEOUT_S)
        return self.status()

    def motors_off(self) -> DeviceStatus:
        self.ready()
        self.link.send(motors_off())
        self.link.wait_idle(COMMAND_TIMEOUT_S)
        return self.status()

    def home(self, timeout_s: float = HOMING_TIMEOUT_S) -> DeviceStatus:
        """Enable every driver and drive the three modules to their endstops (docs/homing.md)."""
        self.ready()
        self.link.send(*home_commands(self.model, self.profile.drive.home_mm))
        self.link.wait_idle(timeout_s)
        return self.status()

    # ---------------------------------------------------------------- heaters
    def set_heaters(
        self, hotend_c: float | None = None, bed_c: float | None = None, *, wait: bool = False
    ) -> DeviceStatus:
        """Set heater targets (None leaves a heater as it is; 0 switches it off); ``wait``
        holds the device's queue until each target set above 0 is reached."""
        self.ready()
        self.link.send(*heater_messages(hotend_c, bed_c, wait=wait))
        if not wait:
            self.link.wait_idle(COMMAND_TIMEOUT_S)
        return self.status()

    def heaters_off(self, timeout_s: float | None = None) -> None:
        self.link.send(*heater_messages(0.0, 0.0), timeout=timeout_s)

    # ----------------------------------------------------------------- motion
    def move_through(
        self,
        points: np.ndarray,
        *,
        feed_mm_s: float | None = None,
        home_if_needed: bool = False,
        timeout_s: float | None = None,
        end_steps: ArrayLike | None = None,
    ) -> MoveResult:
        """Straight moves through ``points`` (machine frame, in order), planned like a print
        (limits, ramps, ends at rest); returns when the device has executed them and waited
        ``settle_s``. ``end_steps`` (module steps): end exactly there (the last point's own
        steps may differ by rounding or backlash; the last segment takes up the difference)."""
        st = self.ready()
        if st.homed_mask & ALL_MODULES != ALL_MODULES:
            if not home_if_needed:
                raise NotHomed("the modules are not homed: home first")
            st = self.home()
        # The wire carries step deltas: plan from the device's module steps with the extruder
        # counter at zero, so a move never tries to undo the filament a print pushed (a print
        # or a cancelled print leaves that counter far from zero).
        modules_only = (*st.steps[:3], 0)
        board = board_caps(self.link, self.profile)  # as a print plans: the board's limits
        wire, seconds, reached = direct_path(
            board.profile,
            self.model,
            state_at_steps(self.model, modules_only),
            points,
            feedrate_mm_s=self.feed_mm_s if feed_mm_s is None else float(feed_mm_s),
            clock_hz=self.clock_hz,
            limits=board.segments,
        )
        limit = timeout_s if timeout_s is not None else seconds + 60.0
        if end_steps is not None:
            wire = end_exactly(wire, reached.steps[:3], end_steps)
        if len(wire):
            self.link.send(enable_all())
            self.link.queue_segments(wire, timeout=limit)
        self.link.wait_idle(limit)
        if self.settle_s > 0:
            self.link.poll(self.settle_s)  # let it come to rest
        after = self.status()
        if after.faulted:
            # a device that faulted mid-move is idle too: the move did not happen as asked
            raise LinkError(
                f"the device stopped during the move (after segment {after.segments_done}): "
                f"{_error_name(after.last_error)}"
            )
        return MoveResult(np.asarray(after.steps[:3], dtype=np.int64), float(self.link.now()))

    def move_to(
        self, target: tuple[float, float, float], *, feed_mm_s: float | None = None
    ) -> DeviceStatus:
        """One straight move to ``target`` (machine frame); the modules must be homed."""
        self.move_through(np.asarray(target, dtype=float).reshape(1, 3), feed_mm_s=feed_mm_s)
        return self.status()

    def park(self, *, lift_mm: float = 10.0) -> DeviceStatus:
        """Lift the effector straight up by ``lift_mm`` (capped at the build volume's top)."""
        st = self.status()
        if st.homed_mask & ALL_MODULES != ALL_MODULES:
            return st
        here = self.model.fk(self.model.sliders_from_steps(np.asarray(st.steps[:3]))[None, :])[0]
        if not np.all(np.isfinite(here)):
            return st
        top = self.profile.build_volume.z_max_mm
        target = (float(here[0]), float(here[1]), float(min(here[2] + lift_mm, top)))
        if target[2] <= here[2]:
            return st
        return self.move_to(target)

    def after_cancel(self) -> DeviceStatus:
        """What the profile asks once a print is cancelled: park (lift clear of the part)
        when ``park.on_cancel``, heaters off when ``heaters.on_cancel`` is "off"."""
        st = self.status()
        if self.profile.park.on_cancel and self.profile.park.lift_mm > 0:
            st = self.park(lift_mm=self.profile.park.lift_mm)
        if self.profile.heaters.on_cancel == "off":
            st = self.set_heaters(0.0, 0.0)
        return st

    def emergency_stop(self, timeout_s: float = 1.0, flags: int = 0) -> bool:
        """Stop now, bypassing the queue: motion and heaters off on the device, the motors
        kept enabled (the effector hangs on them); ``flags``
        (firmware_protocol.messages.EstopFlag) keep the heaters or release the motors."""
        return self.link.emergency_stop(timeout=timeout_s, flags=flags)

    # ------------------------------------------- the wizard's device interface
    def visit(self, points: np.ndarray) -> tuple[np.ndarray, float]:
        """:class:`cdprhost.calibration.wizard.WizardDevice`: move through ``points``, homing
        first when needed; the settled module steps and the device time."""
        moved = self.move_through(points, home_if_needed=True)
        return moved.steps, moved.device_time_s
