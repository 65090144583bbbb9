"""Shared: print a program on the embedded device once, and its planned segments."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cdprhost.gcode.items import MoveChunk
from cdprhost.job.runner import PrintJob, PrintResult
from cdprhost.kinematics import MachineModel
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.program import read_items
from cdprhost.motion.segments import PlannedSegments
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded


@dataclass
class PrintRun:
    path: Path
    result: PrintResult
    record: list[dict]
    steps_abs: np.ndarray  # planned (n, 4)
    lines: np.ndarray  # planned (n,)
    moves_start: dict[int, np.ndarray]
    moves_end: dict[int, np.ndarray]
    e_final: float
    model: MachineModel
    profile: object


def print_embedded(path: Path, profile_name: str = "paper-prototype") -> PrintRun:
    profile = load_profile(profile_name)
    model = MachineModel.from_profile(profile)
    holder = {}

    def factory():
        holder["link"] = open_embedded()
        return holder["link"]

    result = PrintJob(path, profile, factory).run()
    record = list(holder["link"].device.record) if "link" in holder else []
    steps, lines = [], []
    clock = holder["link"].identity.clock_hz if "link" in holder else 100_000
    starts, ends, e_final = {}, {}, 0.0
    origin = np.asarray(profile.build_volume.bed_origin)
    for item in read_items(path, profile, model):
        if isinstance(item, MoveChunk) and len(item):
            for ln, s, e in zip(item.line.tolist(), item.start + origin, item.end + origin):
                starts[ln], ends[ln] = s, e
            e_final = float(item.e_end[-1])
    for out in segment_program(read_items(path, profile, model), profile, model, clock_hz=clock):
        if isinstance(out, PlannedSegments):
            steps.append(out.steps_abs)
            lines.append(out.line)
    return PrintRun(
        path,
        result,
        record,
        np.concatenate(steps),
        np.concatenate(lines),
        starts,
        ends,
        e_final,
        model,
        profile,
    )


def first_layers(
    gcode: Path, out_dir: Path, layers: int, tail: tuple[str, ...] = ("M104 S0",)
) -> Path:
    """The start of a sliced file up to (not including) layer ``layers + 1``, plus ``tail``."""
    lines, seen = [], 0
    for line in gcode.read_text().splitlines():
        if line.startswith(";LAYER_CHANGE"):
            seen += 1
            if seen > layers:
                break
        lines.append(line)
    path = out_dir / f"first-{layers}-layers.gcode"
    path.write_text("\n".join([*lines, *tail]) + "\n")
    return path


@pytest.fixture(scope="session")
def fixture_print(fixture_gcode) -> PrintRun:
    return print_embedded(fixture_gcode)
