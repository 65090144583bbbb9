"""Where the wizard's takes come from: a folder watched for new files, or takes recorded
beforehand (the file whose name ends in the plan pose number). The terminal prompt lives
in the CLI; the TUI hands over the file the user picked."""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdprhost.errors import InputError


@dataclass
class FolderWatcher:
    """Waits for a new take file in ``folder`` (one not seen before), complete and stable."""

    folder: Path
    timeout_s: float = 600.0
    poll_s: float = 0.2
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    seen: set[Path] = field(init=False, default_factory=set)

    def __post_init__(self) -> None:
        self.folder = Path(self.folder)
        self.seen = set(self._files())

    def _files(self) -> dict[Path, int]:
        if not self.folder.is_dir():
            return {}
        return {
            p: p.stat().st_size
            for p in self.folder.iterdir()
            if p.is_file() and not p.name.startswith(".") and not p.name.endswith(".tmp")
        }

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        deadline = self.clock() + self.timeout_s
        sizes: dict[Path, int] = {}
        while True:
            files = self._files()
            new = {p: s for p, s in files.items() if p not in self.seen}
            stable = sorted(
                (p for p, s in new.items() if sizes.get(p) == s and s > 0),
                key=lambda p: p.stat().st_mtime,
            )
            if stable:
                self.seen.update(new)
                return stable[-1]
            sizes = new
            if self.clock() > deadline:
                raise InputError(
                    f"no new take file appeared within {self.timeout_s:g} s",
                    source=str(self.folder),
                )
            self.sleep(self.poll_s)


@dataclass
class NumberedTakes:
    """Takes recorded beforehand: the file whose name ends in the plan pose number (``pose_3.csv``)."""

    folder: Path

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        folder = Path(self.folder)
        for p in sorted(folder.iterdir()) if folder.is_dir() else []:
            numbers = re.findall(r"\d+", p.stem)
            if p.is_file() and numbers and int(numbers[-1]) == index + 1:
                return p
        raise InputError(
            f"no take for plan pose {index + 1} (expected a file name ending in {index + 1})",
            source=str(folder),
        )
