"""Shared by the reset-then-resume tests of both devices: kill the host mid-print, reset the
chip (the DTR auto-reset of the next connect), ``print --resume``, and compare the record
with an uninterrupted print's.

"Equal" is segment for segment, on what the part gets: the segments executed before the
stop are the uninterrupted print's first segments, step for step; the resume's own moves
(homing, lift, travel) end by lowering exactly onto the end of the last executed segment;
from there every segment is the uninterrupted print's: the same module steps (absolute),
the same extruder increment and the same duration. The one exception the comparison
allows is the rest of a move the device was stopped in while moving (physics: it
restarts from rest there, so that move's remaining segments are planned again); every
segment after that move is equal. The extruder keeps the file's absolute E through the
restart and each move's duration is rounded on its own, so nothing drifts.
"""

from __future__ import annotations

from dataclasses import dataclass


def steps(rows: list[dict]) -> list[list[int]]:
    return [r["steps"] for r in rows]


@dataclass
class Comparison:
    prefix_equal: bool  # the first run's segments are the uninterrupted print's first ones
    approach_found: bool  # the resume lowered exactly onto the end of the last executed one
    tail_equal: int  # segments at the end equal to the uninterrupted print's
    rest: int  # uninterrupted segments after the stop
    resumed: int  # segments the resume ran after lowering onto the stop
    last_equal: bool  # same final module steps
    filament_equal: bool  # the same extruder steps from the stop to the end

    @property
    def all_equal(self) -> bool:
        """Every segment from the stop to the end is the uninterrupted print's."""
        return self.tail_equal == self.rest == self.resumed

    @property
    def replaced(self) -> int:
        """The uninterrupted print's segments after the stop that the resume ran otherwise:
        the rest of the move the device stopped in while moving (0 when it stopped at rest)."""
        return self.rest - self.tail_equal


#: the most segments the rest of one move of the test part (a side of the square, cut into
#: pieces of about 1.6 mm) makes: a bound on :attr:`Comparison.replaced`
ONE_MOVE = 15


def _increment(rows: list[dict], i: int, before: dict) -> tuple[int, int]:
    """Extruder steps and duration (us) of row ``i`` (``before``: the row before it)."""
    prev = rows[i - 1] if i > 0 else before
    de = int(rows[i]["steps"][3] - prev["steps"][3])
    return de, round((rows[i]["t"] - prev["t"]) * 1e6)


def compare(clean: list[dict], first: list[dict], resumed: list[dict]) -> Comparison:
    """``first``: rows executed before the reset (the program's, errors dropped);
    ``resumed``: rows of the resumed print.

    Segments compare from the end: equal when the module steps, the extruder increment
    and the duration are the same."""
    n = len(first)
    prefix_equal = steps(first) == steps(clean[:n])
    stop = first[-1] if first else None
    at = next(
        (
            i
            for i, r in enumerate(resumed)
            if stop is not None and r["steps"][:3] == stop["steps"][:3]
        ),
        None,
    )
    rest = clean[n:]
    program = resumed[at + 1 :] if at is not None else []
    k = 0
    while stop is not None and at is not None and k < min(len(rest), len(program)):
        a, b = len(rest) - 1 - k, len(program) - 1 - k
        if rest[a]["steps"][:3] != program[b]["steps"][:3] or _increment(
            rest, a, stop
        ) != _increment(program, b, resumed[at]):
            break
        k += 1
    filament_equal = (
        bool(program)
        and stop is not None
        and at is not None
        and clean[-1]["steps"][3] - stop["steps"][3]
        == program[-1]["steps"][3] - resumed[at]["steps"][3]
    )
    return Comparison(
        prefix_equal,
        at is not None,
        k,
        len(rest),
        len(program),
        bool(program) and program[-1]["steps"][:3] == clean[-1]["steps"][:3],
        filament_equal,
    )
