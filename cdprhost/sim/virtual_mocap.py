"""Virtual motion capture beside the simulated device (``--truth PROFILE --mocap-dir DIR``).

The simulated device calls ``on_settled(steps, device_time_s)`` whenever motion
has stopped and the queue has stayed empty for its settle time
(``SimConfig.settle_s``). The observer works out where the effector of a hidden
*true* machine really is for those absolute steps (the truth profile's forward
kinematics with its effects: backlash needs each module's last direction of
motion, drift the time) and writes a motion-capture take of that point into the
mocap folder, an OptiTrack Motive CSV (in metres) by default, with the noise of a
real system (:data:`REALISTIC`: autocorrelated jitter of 0.1 mm per marker at 120 fps,
a settling swing after each move, runs of gaps; ``creep_probability`` of a slow creep).
``creep_takes`` (take numbers, from 1) creep by ``creep_mm`` for sure; ``offset_takes``
(take number -> vector, mm) are displaced, as by a bumped effector or a wrong marker. ``crept`` records,
per take written, whether it crept. Takes use the synthetic session layout's markers
(:mod:`cdprhost.sim.synthetic_session`); :func:`mocap_config` is the matching
``[mocap]`` configuration. ``make_observer(None, None)`` is None (no observer).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Collection, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.calibration.mocap.readers import EXTENSIONS
from cdprhost.calibration.session import SessionConfig
from cdprhost.errors import InputError
from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile
from cdprhost.sim.mocap_noise import MocapNoise, vary
from cdprhost.sim.synthetic_session import (
    DEFAULT_BASE_MARKERS,
    DEFAULT_EFFECTOR_MARKERS,
    synthesize_take,
    synthetic_config,
)
from cdprhost.sim.true_effector import TrueEffector

#: What the virtual motion capture adds by default: a good but not perfect system.
REALISTIC = MocapNoise(
    jitter_mm=0.1,
    correlation_s=0.015,
    marker_variation=0.3,
    settle_mm=0.4,
    settle_hz=3.0,
    settle_decay_s=0.2,
    gap_fraction=0.02,
    gap_run_frames=12.0,
)


class VirtualMocap:
    """Observer writing one take per settle into ``directory`` (``take-0001.csv``, ...).

    ``directions`` (sign of each module's last motion) feed the truth's backlash:
    passed by the device, or read from the device's record of executed segments
    (:meth:`attach_record`), or else inferred from the change of steps since the
    previous settle (right only for moves straight into a pose).
    """

    def __init__(
        self,
        truth: MachineModel,
        directory: str | os.PathLike[str],
        *,
        realism: MocapNoise | None = None,
        rate_hz: float = 120.0,
        duration_s: float = 2.0,
        creep_probability: float = 0.0,
        creep_takes: Collection[int] = (),
        creep_mm: float = 0.3,
        offset_takes: Mapping[int, ArrayLike] | None = None,
        noise_mm: float = 0.0,
        seed: int | None = 0,
        format: str = "motive-csv",
        writer_options: dict[str, Any] | None = None,
    ):
        self.truth = truth
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.realism = REALISTIC if realism is None else realism
        self.rate_hz = float(rate_hz)
        self.n_frames = max(int(round(duration_s * rate_hz)), 2)
        self.creep_probability = float(creep_probability)
        self.creep_takes = frozenset(int(n) for n in creep_takes)
        self.creep_mm = float(creep_mm)
        self.offset_takes = {
            int(k): np.asarray(v, dtype=float).reshape(3) for k, v in (offset_takes or {}).items()
        }
        self.noise_mm = float(noise_mm)
        self.crept: list[bool] = []
        self.format = format
        default_options = {"units": "Meters", "version": "1.23"} if format == "motive-csv" else {}
        self.writer_options = dict(default_options if writer_options is None else writer_options)
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._tracker = TrueEffector(truth)
        self.count = sum(1 for p in self.directory.glob("take-*") if not p.name.startswith("."))
        self.written: list[Path] = []

    def attach_record(self, record: Any) -> None:
        """Read last-motion directions from the device's record of executed segments."""
        self._tracker.attach_record(record)

    def _record_directions(self, window: int = 4096) -> np.ndarray | None:
        return self._tracker.record_directions(window)

    def effector_point(
        self, steps: ArrayLike, device_time_s: float, directions: ArrayLike | None = None
    ) -> np.ndarray:
        """Where the true effector is for absolute module steps (the first three of ``steps``)."""
        return self._tracker.effector_point(steps, device_time_s, directions)

    def on_settled(
        self, steps: ArrayLike, device_time_s: float, directions: ArrayLike | None = None
    ) -> Path | None:
        """Write a take of the settled effector; returns its path (None if the cables cannot meet)."""
        with self._lock:
            point = self._tracker.settle(steps, device_time_s, directions)
            if not np.isfinite(point).all():
                return None
            self.count += 1
            point = point + self.offset_takes.get(self.count, 0.0)
            path = self.directory / f"take-{self.count:04d}{EXTENSIONS[self.format]}"
            noise = vary(self.realism, self._rng, creep_probability=self.creep_probability)
            if self.count in self.creep_takes:
                noise = replace(noise, creep_mm=self.creep_mm)
            self.crept.append(noise.creep_mm > 0)
            synthesize_take(
                point,
                noise_mm=self.noise_mm,
                realism=noise,
                n_frames=self.n_frames,
                rate_hz=self.rate_hz,
                rng=self._rng,
                path=path,
                format=self.format,
                **self.writer_options,
            )
            self.written.append(path)
            return path


def mocap_config(profile_name: str = "truth", format: str = "motive-csv") -> SessionConfig:
    """The session configuration that reads this observer's takes."""
    return synthetic_config(profile_name, format, DEFAULT_BASE_MARKERS, DEFAULT_EFFECTOR_MARKERS)


def make_observer(
    truth_profile_path: str | os.PathLike[str] | None,
    mocap_dir: str | os.PathLike[str] | None,
    **options: Any,
) -> VirtualMocap | None:
    """The device's observer factory: both arguments, or neither (None)."""
    if truth_profile_path is None and mocap_dir is None:
        return None
    if truth_profile_path is None or mocap_dir is None:
        given, missing = (
            ("--truth", "--mocap-dir") if mocap_dir is None else ("--mocap-dir", "--truth")
        )
        raise InputError(
            f"{given} needs {missing} too (virtual motion capture needs a true machine and a folder for its takes)"
        )
    truth = MachineModel.from_profile(load_profile(truth_profile_path))
    return VirtualMocap(truth, mocap_dir, **options)
