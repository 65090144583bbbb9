"""The G-code the benchmarks read: the team's fixture when it is beside the repository
(``../shared/fixtures/part-prusaslicer.gcode``, or under ``$CDPRHOST_SHARED``), else the
example the repository ships (``examples/example.gcode``, the same kind of file, smaller),
so every benchmark runs from a fresh clone and says in one line which file it measured."""

from __future__ import annotations

import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("CDPRHOST_SHARED", REPO.parent / "shared"))
TEAM_FIXTURE = SHARED / "fixtures" / "part-prusaslicer.gcode"
EXAMPLE = REPO / "examples" / "example.gcode"


def gcode_fixture(given: Path | None = None) -> Path:
    """``given`` when set (it must exist), else the team's fixture, else the example."""
    if given is not None:
        if not Path(given).is_file():
            raise SystemExit(f"{sys.argv[0]}: {given}: no such G-code file")
        return Path(given)
    if TEAM_FIXTURE.is_file():
        return TEAM_FIXTURE
    if EXAMPLE.is_file():
        lines = sum(1 for _ in EXAMPLE.open("rb"))
        print(
            f"(the team's fixture {TEAM_FIXTURE} is not here: measuring {EXAMPLE.relative_to(REPO)}"
            f", {lines} lines; set CDPRHOST_SHARED or pass a file for the fixture's figures)",
            file=sys.stderr,
        )
        return EXAMPLE
    raise SystemExit(
        f"{sys.argv[0]}: needs a G-code file: {TEAM_FIXTURE} or {EXAMPLE} (or pass one)"
    )
