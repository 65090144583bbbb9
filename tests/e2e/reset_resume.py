"""Shared by the reset-then-resume tests of both devices: kill the host mid-print, reset the
chip (the DTR auto-reset of the next connect), ``print --resume``, and compare the record
with an uninterrupted print's.

"Equal" is defined on what the part gets: the segments executed before the stop are the
uninterrupted print's first segments, step for step; after the resume's own moves (homing,
lift, travel, lowering onto the end of the last executed segment) the rest of the cut move
is planned again from rest, so its segments differ until the next rest point; from there
on every segment's module steps, and every extruder increment, are the uninterrupted
print's (the filament axis is re-zeroed at the restart, so only its increments compare).
"""

from __future__ import annotations

from dataclasses import dataclass


def steps(rows: list[dict]) -> list[list[int]]:
    return [r["steps"] for r in rows]


@dataclass
class Comparison:
    prefix_equal: bool  # the first run's segments are the uninterrupted print's first ones
    approach_found: bool  # the resume lowered exactly onto the end of the last executed one
    tail_equal: int  # segments at the end equal to the uninterrupted print's (xyz, E steps)
    rest: int  # uninterrupted segments after the stop
    last_equal: bool  # same final module steps


def compare(clean: list[dict], first: list[dict], resumed: list[dict]) -> Comparison:
    """``first``: rows executed before the reset (the program's, errors dropped);
    ``resumed``: rows of the resumed print."""
    n = len(first)
    prefix_equal = steps(first) == steps(clean[:n])
    stop = first[-1]["steps"][:3] if first else None
    at = next((i for i, r in enumerate(resumed) if r["steps"][:3] == stop), None)
    rest = clean[n:]
    program = resumed[at + 1 :] if at is not None else []

    def key(rows: list[dict], i: int) -> tuple[object, ...]:
        e = rows[i]["steps"][3] - rows[i - 1]["steps"][3] if i > 0 else None
        return (*rows[i]["steps"][:3], e)

    k = 0
    while k < min(len(rest), len(program)) - 1:
        if key(rest, len(rest) - 1 - k) != key(program, len(program) - 1 - k):
            break
        k += 1
    return Comparison(
        prefix_equal,
        at is not None,
        k,
        len(rest),
        bool(program) and program[-1]["steps"][:3] == clean[-1]["steps"][:3],
    )
