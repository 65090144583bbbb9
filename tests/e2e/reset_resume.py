"""Shared by the reset-then-resume tests of both devices: kill the host mid-print, reset the
chip (the DTR auto-reset of the next connect), ``print --resume``, and compare the record
with an uninterrupted print's.

"Equal" is defined on what the part gets: the segments executed before the stop are the
uninterrupted print's first segments, step for step; after the resume's own moves (homing,
lift, travel, lowering onto the end of the last executed segment) the rest of the cut move
is planned again from rest, so its segments differ until the next rest point; from there
on every segment's module steps are the uninterrupted print's, its extruder increment
within one step (the filament axis is re-zeroed at the restart), and the extruder's
total from the stop to the end is the same.
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
    last_equal: bool  # same final module steps
    filament_equal: bool  # the same extruder steps from the stop to the end


def compare(clean: list[dict], first: list[dict], resumed: list[dict]) -> Comparison:
    """``first``: rows executed before the reset (the program's, errors dropped);
    ``resumed``: rows of the resumed print.

    A segment at the end compares equal when its module steps are the same and its
    extruder increment is within one step: the filament axis is re-zeroed at the restart
    (by the program's E there, a fraction of a step), so a segment's rounding may move one
    step to its neighbour; the extruder's total from the stop to the end must be equal."""
    n = len(first)
    prefix_equal = steps(first) == steps(clean[:n])
    stop = first[-1]["steps"] if first else None
    at = next(
        (i for i, r in enumerate(resumed) if stop is not None and r["steps"][:3] == stop[:3]),
        None,
    )
    rest = clean[n:]
    program = resumed[at + 1 :] if at is not None else []

    def de(rows: list[dict], i: int) -> int:
        return int(rows[i]["steps"][3] - rows[i - 1]["steps"][3])

    k = 0
    while k < min(len(rest), len(program)) - 1:
        a, b = len(rest) - 1 - k, len(program) - 1 - k
        if rest[a]["steps"][:3] != program[b]["steps"][:3] or abs(de(rest, a) - de(program, b)) > 1:
            break
        k += 1
    filament_equal = (
        bool(program)
        and stop is not None
        and at is not None
        and clean[-1]["steps"][3] - stop[3] == program[-1]["steps"][3] - resumed[at]["steps"][3]
    )
    return Comparison(
        prefix_equal,
        at is not None,
        k,
        len(rest),
        bool(program) and program[-1]["steps"][:3] == clean[-1]["steps"][:3],
        filament_equal,
    )
