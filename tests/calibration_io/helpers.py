"""Shared test data for the calibration I/O tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdprhost.calibration.mocap.readers import Take
from cdprhost.calibration.mocap.takes import EffectorConfig, MocapConfig
from cdprhost.sim.synthetic_session import (
    DEFAULT_BASE_MARKERS,
    DEFAULT_EFFECTOR_MARKERS,
    effector_offset,
)

DATA = Path(__file__).resolve().parent / "data"
# The point the hand-written sample takes were made from (base frame, mm).
SAMPLE_POINT = np.array([12.5, -20.0, 180.0])

SPEC_SESSION_TOML = """\
[session]
profile = "paper-simulation"        # profile (name or path) that commanded the poses

[mocap]
format = "motive-csv"               # motive-csv | vicon-csv | qualisys-tsv | c3d
                                    # (readers should also detect it from the file)

[mocap.base_markers]                # marker name in the take -> its position in the
"Base:F1" = [0.0, 300.0, 0.0]       # base frame (mm). At least 3, not collinear.
"Base:F2" = [-259.8, -150.0, 0.0]
"Base:F3" = [259.8, -150.0, 0.0]

[mocap.effector]
markers = ["EE:E1", "EE:E2", "EE:E3"]   # the centroid of these markers...
offset = [0.0, 0.0, -12.0]              # ...plus this vector (base frame, mm) is B
"""


def mocap_config(rename=lambda n: n, **acceptance) -> MocapConfig:
    return MocapConfig(
        base_markers={rename(k): v for k, v in DEFAULT_BASE_MARKERS.items()},
        effector=EffectorConfig(
            markers=tuple(rename(k) for k in DEFAULT_EFFECTOR_MARKERS),
            offset=effector_offset(DEFAULT_EFFECTOR_MARKERS),
        ),
        acceptance=acceptance or {},
    )


def random_take(
    rng: np.random.Generator,
    n_frames: int = 15,
    names=("Base:F1", "Base:F2", "EE:E1", "EE:E2"),
    gaps: float = 0.1,
    spread_mm: float = 800.0,
) -> Take:
    pos = rng.uniform(-spread_mm, spread_mm, (n_frames, len(names), 3))
    pos[rng.random(pos.shape[:2]) < gaps] = np.nan
    return Take(tuple(names), pos, np.arange(n_frames) / 120.0, "<random>", "motive-csv")
