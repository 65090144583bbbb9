"""Motion limits a connected device imposes: its announced step rate caps the speeds.

A profile may allow module or filament speeds that need more steps per second than the
device can issue (it announces ``max_step_rate`` in its handshake). Rather than refuse
the file, the host plans the print slower and says so: the caps below keep every axis
under the device's rate with a margin: a segment's peak rate is a little above the
planner's continuous speed, and a microcontroller's step timing degrades near its
limit when several axes step fast at once (the AVR firmware's README gives figures).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.motion.block_cuts import BlockLimits
from cdprhost.motion.moves import MIN_MOVE_MM
from cdprhost.motion.segments import DEFAULT_LIMITS, MIN_SEGMENT_S, SegmentLimits
from cdprhost.profile.device_record import DeviceRecord
from cdprhost.profile.models import MachineProfile

#: plan for at most this fraction of the announced rate
STEP_RATE_MARGIN = 0.9


@dataclass(frozen=True)
class DeviceCaps:
    """The profile to plan with and, when it had to be slowed, what changed (one line);
    the limits the segments keep to (the device's shortest segment and step rate)."""

    profile: MachineProfile
    notice: str | None
    segments: SegmentLimits = DEFAULT_LIMITS


def caps_for_device(
    profile: MachineProfile,
    max_step_rate: float | None,
    min_segment_s: float | None = None,
    blocks: BlockLimits | None = None,
    total_step_rate: float | None = None,
) -> DeviceCaps:
    """``profile`` with module and extruder speeds capped to ``max_step_rate`` (steps/s
    on any one axis, as the device announced); unchanged when it already fits or the
    device announced nothing. The segments keep to the rate and to the device's
    shortest segment (``min_segment_s``, from its CAPS) after rounding, and with
    ``blocks`` (a device that steps from schedule blocks) ramps are cut until their blocks
    fit a frame (block_cuts). ``total_step_rate`` (STEP_BUDGET, 3.3: what the device's
    axes take summed) caps each move's speed by the steps all its axes take per mm."""
    segments = SegmentLimits(
        max(MIN_SEGMENT_S, min_segment_s or 0.0),
        None if max_step_rate is None else float(max_step_rate),
        blocks,
        None if total_step_rate is None else float(total_step_rate),
    )
    motion, extruder = profile.motion, profile.extruder
    if total_step_rate is not None:
        total = STEP_RATE_MARGIN * float(total_step_rate)
        if motion.max_total_step_rate is None or motion.max_total_step_rate > total:
            motion = motion.model_copy(update={"max_total_step_rate": total})
    said = []
    if max_step_rate is not None:
        rate = STEP_RATE_MARGIN * float(max_step_rate)
        module_cap = rate / max(profile.drive.steps_per_mm)
        extruder_cap = rate / profile.extruder.steps_per_mm
        if motion.module_max_velocity_mm_s > module_cap:
            said.append(
                f"module speed {module_cap:.1f} mm/s (profile {motion.module_max_velocity_mm_s:g})"
            )
            motion = motion.model_copy(update={"module_max_velocity_mm_s": module_cap})
        if extruder.max_velocity_mm_s > extruder_cap:
            said.append(
                f"filament speed {extruder_cap:.1f} mm/s (profile {extruder.max_velocity_mm_s:g})"
            )
            extruder = extruder.model_copy(update={"max_velocity_mm_s": extruder_cap})
    notice = (
        f"the device steps at most {max_step_rate:g}/s per axis: planned with " + " and ".join(said)
        if said
        else None
    )
    if motion is not profile.motion or extruder is not profile.extruder:
        profile = profile.model_copy(update={"motion": motion, "extruder": extruder})
    return DeviceCaps(profile, notice, segments)


#: the axes a board's step rate can limit, in the order :func:`busiest_axis` numbers them
AXES = ("module 1", "module 2", "module 3", "the extruder")
#: an axis is named as limiting when it carries at least this share of the time lost
NAMED_SHARE = 0.1


def busiest_axis(
    start: np.ndarray,
    end: np.ndarray,
    extrusion: np.ndarray,
    outlets: np.ndarray,
    steps_per_mm: np.ndarray,
    e_steps_per_mm: float,
) -> np.ndarray:
    """(n,) index into :data:`AXES` of the axis that needs the most steps per mm of path in
    the middle of each straight move ``start`` -> ``end`` (machine frame, mm; ``extrusion``
    mm of filament): the one a step-rate cap holds back. Extrude-only moves: the extruder."""
    delta = end - start
    dist = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    kin = dist > MIN_MOVE_MM
    unit = delta / np.where(kin, dist, 1.0)[:, None]
    cable = 0.5 * (start + end)[:, None, :] - outlets[None, :, :]  # (n, 3 cables, xyz)
    cable /= np.sqrt(np.einsum("nkj,nkj->nk", cable, cable))[:, :, None]
    rates = np.empty((delta.shape[0], 4))
    rates[:, :3] = np.abs(np.einsum("nkj,nj->nk", cable, unit)) * steps_per_mm
    rates[:, 3] = np.abs(extrusion) / np.where(kin, dist, 1.0) * e_steps_per_mm
    rates[~kin, :3] = 0.0
    return np.asarray(np.argmax(rates, axis=1))


def slowed_axes(lost_s: np.ndarray) -> list[tuple[str, float]]:
    """The axes that carry at least :data:`NAMED_SHARE` of the time lost (``lost_s``: s per
    axis of :data:`AXES`), with their share, the largest first."""
    total = float(np.clip(lost_s, 0.0, None).sum())
    if total <= 0.0:
        return []
    order = np.argsort(-lost_s, kind="stable")
    return [(AXES[k], float(lost_s[k]) / total) for k in order if lost_s[k] >= NAMED_SHARE * total]


def slowdown_message(
    max_step_rate: int,
    axes: list[tuple[str, float]],
    board_s: float,
    free_s: float,
    total_step_rate: int | None = None,
) -> str:
    """e.g. "the board's 10,000 steps/s limits module 2: +31 % (978 s instead of 747 s)";
    a board with a budget its axes share (``total_step_rate``) says "the board's 26,000
    steps/s (80,000 in all) limits ..."."""
    if len(axes) == 1:
        names = axes[0][0]
    else:
        names = ", ".join(f"{name} ({100.0 * share:.0f} %)" for name, share in axes)
    pct = 100.0 * (board_s - free_s) / free_s if free_s > 0 else 0.0
    rate = f"{max_step_rate:,} steps/s"
    if total_step_rate is not None:
        rate += f" ({total_step_rate:,} in all)"
    return (
        f"the board's {rate} limits {names or 'no axis'}: {pct:+.0f} % "
        f"({board_s:.0f} s instead of {free_s:.0f} s at the profile's own limits)"
    )


def same_board_plan(
    profile: MachineProfile, a: DeviceRecord | None, b: DeviceRecord | None
) -> bool:
    """Boards recorded as ``a`` and ``b`` (None: unknown) get the same plan from
    ``profile`` (their estimates agree)."""

    def plan(rec: DeviceRecord | None) -> MachineProfile:
        if rec is None:
            return caps_for_device(profile, None).profile
        return caps_for_device(
            profile, rec.max_step_rate, total_step_rate=rec.total_step_rate
        ).profile

    return plan(a) == plan(b)
