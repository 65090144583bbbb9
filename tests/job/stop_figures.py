"""A print with a pause or cancel requested at a given program time, on the embedded device
(device time at 1x), and the figures of its stop read from the device's record: latency
from the request to rest in device seconds, the deceleration, what the extruder did.

Shared by tests/job/test_stop_within_buffer.py and ``bench/stop.py``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdprhost.job.runner import PrintJob, PrintOptions, PrintResult
from cdprhost.job.state import JobState, Progress, StateChanged
from cdprhost.kinematics.machine import MachineModel
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded

CUP = Path(__file__).resolve().parents[2] / "examples" / "example.gcode"


@dataclass
class StopRun:
    job: PrintJob
    result: PrintResult
    record: list[dict[str, Any]]
    requested_t: float  # device motion clock at the request (s)
    states: list[JobState]
    link: Any

    @property
    def stop(self) -> Any:
        assert self.job.last_stop is not None
        return self.job.last_stop

    def by_seq(self, seq: int) -> dict[str, Any]:
        return next(r for r in self.record if r["seq"] == seq)

    @property
    def latency_s(self) -> float:
        """Device seconds from the request to rest (the end of the retract)."""
        return float(self.by_seq(self.stop.last_segment)["t"]) - self.requested_t

    def window(self, before: int = 6) -> list[dict[str, Any]]:
        """Record entries from ``before`` segments ahead of the stop to its end."""
        lo, hi = self.stop.first_segment - before, self.stop.last_segment
        return [r for r in self.record if lo <= r["seq"] <= hi]


def speeds(model: MachineModel, entries: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """Mean effector speed (mm/s) of each entry after the first, and the mid times (s)."""
    steps = np.asarray([r["steps"][:3] for r in entries], dtype=np.int64)
    t = np.asarray([r["t"] for r in entries], dtype=float)
    pts = model.fk(model.sliders_from_steps(steps))
    dist = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    dt = np.diff(t)
    return dist / np.maximum(dt, 1e-9), (t[1:] + t[:-1]) / 2


def peak_decel(model: MachineModel, entries: list[dict[str, Any]]) -> float:
    """The largest fall of the mean speed between consecutive segments, per second (mm/s^2)."""
    v, mid = speeds(model, entries)
    if len(v) < 2:
        return 0.0
    return float(max(0.0, np.max(-np.diff(v) / np.maximum(np.diff(mid), 1e-9))))


def run_with_request(
    gcode: Path,
    what: str,
    at_s: float,
    tmp: Path,
    *,
    profile_name: str = "paper-prototype",
    resume_after: bool = True,
) -> StopRun:
    """Print ``gcode``; at program time ``at_s`` request ``what`` ("pause" or "cancel");
    a pause is resumed once paused (when ``resume_after``)."""
    profile = load_profile(profile_name)
    holder: dict[str, Any] = {}
    states: list[JobState] = []

    def factory() -> Any:
        holder["link"] = open_embedded()
        return holder["link"]

    def on_event(e: Any) -> None:
        if isinstance(e, Progress) and e.device_time_s >= at_s and "t" not in holder:
            dev = holder["link"].device
            holder["t"] = dev.machine.motion_ticks / dev.config.clock_hz
            getattr(job, f"request_{what}")()
        if isinstance(e, StateChanged):
            states.append(e.state)
            if e.state is JobState.PAUSED and resume_after:
                threading.Timer(0.05, job.request_resume).start()

    options = PrintOptions(resume_dir=tmp / "resume", log_path=tmp / "job.jsonl")
    job = PrintJob(gcode, profile, factory, options, on_event=on_event)
    result = job.run()
    link = holder["link"]
    return StopRun(job, result, list(link.device.record), holder.get("t", 0.0), states, link)


def fast_circles(
    path: Path, feed_mm_s: float = 120.0, loops: int = 20, radius: float = 30.0
) -> Path:
    """Loops of a circle extruded at ``feed_mm_s`` (1 degree chords: the plan keeps its speed
    all the way round), so a stop almost anywhere starts at full speed and decelerates along
    a curved path over several segments."""
    lines = ["G28", "M104 S200", "M109 S200", "G92 E0", "M83", "G1 Z0.3 F3000"]
    lines.append(f"G1 X{radius:.3f} Y0 F6000")
    step = np.deg2rad(1.0)
    chord = 2 * radius * np.sin(step / 2)
    for k in range(1, 360 * loops + 1):
        a = k * step
        lines.append(
            f"G1 X{radius * np.cos(a):.3f} Y{radius * np.sin(a):.3f} E{chord * 0.05:.4f} "
            f"F{feed_mm_s * 60:.0f}"
        )
    path.write_text("\n".join([*lines, "M104 S0"]) + "\n")
    return path
