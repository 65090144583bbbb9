"""The program as this machine will run it: read, placed, retargeted, objects cancelled.

``check`` and ``print`` (and the TUI) take the same `Setup` (``--center``,
``--offset``, ``--retarget``, ``--cancel-object``) and get the same stream of items
from `Prepared.items`, so what preflight checked is exactly what prints.

- Placement shifts the whole program in X/Y (the reader adds it to every absolute
  coordinate; homing and the machine's own points do not move). ``--center`` puts
  the part's box (extruding moves from the first layer on) on the build volume's
  centre; ``--offset`` adds its own shift.
- ``--retarget`` replaces the file's start and end blocks with the profile's
  (`cdprhost.gcode.retarget`) and centres the part.
- Cancelled objects are skipped (`cdprhost.gcode.objects.exclude_objects`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.file_copy import FileCopy, copy_file, file_stamp
from cdprhost.gcode.items import ProgramItem
from cdprhost.gcode.objects import exclude_objects
from cdprhost.gcode.placement import PartExtent, centre_offset
from cdprhost.gcode.reader import read_program
from cdprhost.gcode.retarget import RetargetPlan, plan_retarget, retarget_items
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.program import reader_settings
from cdprhost.profile.models import MachineProfile


@dataclass(frozen=True)
class Setup:
    """How to run a file: placement, retargeting, objects to skip."""

    center: bool = False
    offset: tuple[float, float] = (0.0, 0.0)
    retarget: bool = False
    cancel_objects: tuple[str, ...] = ()

    @property
    def default(self) -> bool:
        """Nothing asked: the file as it is."""
        return self == Setup()

    def options(self) -> str:
        """The command-line options that ask for this setup (``"none"`` for the default)."""
        parts = ["--center"] if self.center else []
        if self.offset != (0.0, 0.0):
            parts.append(f"--offset {self.offset[0]:g},{self.offset[1]:g}")
        parts += ["--retarget"] if self.retarget else []
        parts += [f"--cancel-object {name}" for name in self.cancel_objects]
        return " ".join(parts) or "none"

    def to_json(self) -> dict[str, object]:
        return {
            "center": self.center,
            "offset": [self.offset[0], self.offset[1]],
            "retarget": self.retarget,
            "cancel_objects": list(self.cancel_objects),
        }

    @classmethod
    def from_json(cls, data: object) -> Setup:
        """The setup saved by :meth:`to_json`; ValueError naming the field when malformed."""
        if not isinstance(data, dict):
            raise ValueError("setup: not a JSON object")
        center, retarget = data.get("center", False), data.get("retarget", False)
        offset, cancel = data.get("offset", [0.0, 0.0]), data.get("cancel_objects", [])
        if not isinstance(center, bool) or not isinstance(retarget, bool):
            raise ValueError("setup: center and retarget must be true or false")
        if (
            not isinstance(offset, list)
            or len(offset) != 2
            or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in offset)
        ):
            raise ValueError("setup: offset must be two finite numbers")
        if not isinstance(cancel, list) or not all(isinstance(n, str) for n in cancel):
            raise ValueError("setup: cancel_objects must be a list of names")
        return cls(center, (float(offset[0]), float(offset[1])), retarget, tuple(cancel))


def build_volume_centre(profile: MachineProfile) -> tuple[float, float]:
    """The build triangle's centre (machine X/Y = 0) in the G-code frame."""
    ox, oy, _ = profile.build_volume.bed_origin
    return (-float(ox), -float(oy))


@dataclass(frozen=True)
class Prepared:
    path: str
    profile: MachineProfile
    model: MachineModel
    setup: Setup
    placement: tuple[float, float]  # the X/Y shift applied to the file (mm)
    plan: RetargetPlan | None
    #: the file as prepared (size, modification time, inode; None: not a file to stat)
    stamp: tuple[int, int, int] | None = None
    #: the job's private copy of the file (``prepare(copy=True)``), which every read reads
    copy: FileCopy | None = None

    @property
    def sha256(self) -> str | None:
        """The hash of the bytes printed (those of the copy; None without one)."""
        return None if self.copy is None else self.copy.sha256

    def items(self) -> Iterator[ProgramItem]:
        """A fresh stream of the program's items (every call reads the file again). With
        a copy, the copy's: the file may change meanwhile. Without one, a file changed
        since it was prepared (overwritten by a new slice, truncated while read) is a
        GcodeError, before its first item or after its last: never a shorter print that
        looks whole."""
        settings = reader_settings(self.profile, self.model)
        mute = self.plan.mute if self.plan else ()
        items: Iterable[ProgramItem]
        if self.copy is not None:
            items = _holding(
                read_program(
                    self.copy.path, placement=self.placement, mute=mute, name=self.path, **settings
                ),
                self.copy,
            )
        else:
            items = _unchanged(
                read_program(self.path, placement=self.placement, mute=mute, **settings),
                self.path,
                self.stamp,
            )
        if self.plan is not None:
            items = retarget_items(
                items,
                self.plan,
                self._profile_code("start", None),
                self._end_code,
                settings["home_position"],
            )
        if self.setup.cancel_objects:
            items = exclude_objects(items, self.setup.cancel_objects, settings["home_position"])
        return iter(items)

    def _profile_code(self, which: str, here: np.ndarray | None) -> Iterator[ProgramItem]:
        gc = self.profile.gcode
        plan = self.plan
        text = gc.filled(
            gc.start if which == "start" else gc.end,
            plan.hotend_c if plan else None,
            plan.bed_c if plan else None,
        )
        settings = reader_settings(self.profile, self.model)
        start = None if here is None else (float(here[0]), float(here[1]), float(here[2]))
        return read_program(
            text.splitlines(),
            name=f"profile {self.profile.name} [gcode] {which}",
            start_position=start,
            **settings,
        )

    def _end_code(self, here: np.ndarray) -> Iterator[ProgramItem]:
        return self._profile_code("end", here)


def _unchanged(
    items: Iterable[ProgramItem], path: str, stamp: tuple[int, int, int] | None
) -> Iterator[ProgramItem]:
    """``items``, checked against the file's ``stamp`` before the first and after the last."""

    def check() -> None:
        if stamp is not None and file_stamp(path) != stamp:
            raise GcodeError(
                path,
                0,
                0,
                "the file changed after it was checked (written again or truncated); "
                "nothing more of it is printed: check and print it again",
            )

    check()
    yield from items
    check()


def _holding(items: Iterable[ProgramItem], copy: FileCopy) -> Iterator[ProgramItem]:
    """``items``, keeping ``copy`` (and so its file) while they are read."""
    yield from items
    del copy


def prepare(
    path: str | os.PathLike[str],
    profile: MachineProfile,
    model: MachineModel | None = None,
    setup: Setup | None = None,
    copy: bool = False,
    copy_folder: str | os.PathLike[str] | None = None,
) -> Prepared:
    """Decide the placement (and the blocks to replace): one extra read of the file for
    ``--center`` and ``--retarget``, none otherwise. ``copy``: read the file once into a
    private copy (in ``copy_folder``, default the system's temporary folder) that every
    later read reads, as a print must (`cdprhost.gcode.file_copy`)."""
    model = model or MachineModel.from_profile(profile)
    setup = setup or Setup()
    source = os.fspath(path)
    stamp = file_stamp(source)
    kept = copy_file(source, copy_folder) if copy else None
    readable = kept.path if kept is not None else source
    offset = setup.offset
    plan = None
    if setup.center or setup.retarget:
        first = read_program(readable, name=source, **reader_settings(profile, model))
        if setup.retarget:
            plan = plan_retarget(first, readable)
            extent = plan.extent
        else:
            extent = PartExtent.of(first)
        if extent.empty:
            raise GcodeError(
                source, 0, 0, "no extruding moves from the first layer on: no part to place"
            )
        dx, dy = centre_offset(extent, build_volume_centre(profile))
        offset = (dx + offset[0], dy + offset[1])
    placement = (float(offset[0]), float(offset[1]))
    return Prepared(source, profile, model, setup, placement, plan, stamp, kept)
