"""Objects of the plate: M486 and Klipper's EXCLUDE_OBJECT_* labels, and cancelling them.

The reader turns the labels into `ObjectDefine`/`ObjectStart`/`ObjectEnd` records and
the file's own cancellations (``M486 P<id>``, ``EXCLUDE_OBJECT NAME=...``) into
`CancelObject`. `exclude_objects` is the stream stage that skips the moves of
cancelled objects (cancelled in the file or by the user): the machine travels over
them and the filament they would have used stays on the spool.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from typing import NoReturn

import numpy as np

from cdprhost.gcode.items import (
    CancelObject,
    HomeCommand,
    MoveChunk,
    ObjectDefine,
    ObjectEnd,
    ObjectStart,
    ProgramItem,
    UnknownCommand,
)
from cdprhost.gcode.state import ModalState
from cdprhost.gcode.stream import Gap

Fail = Callable[..., NoReturn]
_M486_WORD = re.compile(r'([A-Za-z])[ \t]*("[^"]*"?|[^ \t"]*)')
MAX_OBJECTS = 10000


def m486(text: str, line: int, st: ModalState, fail: Fail) -> list[ProgramItem]:
    """``M486 T<count> | S<id> [A<label>] | S-1 | A<label> | P<id> | U<id> | C``."""
    words: dict[str, str] = {}
    for m in _M486_WORD.finditer(text):
        letter, value = m.group(1).upper(), m.group(2)
        if letter == "A":
            words["A"] = (
                text[m.start(2) :].strip().strip('"')
                if not value.startswith('"')
                else value.strip('"')
            )
            break
        words[letter] = value
    out: list[ProgramItem] = []

    def ident(letter: str) -> int:
        try:
            v = float(words[letter])
        except ValueError:
            fail(f"malformed number '{letter}{words[letter]}'", letter)
        if v != int(v) or v < -1 or v >= MAX_OBJECTS:
            fail(
                f"object id {letter}{words[letter]} is not a whole number in -1..{MAX_OBJECTS - 1}",
                letter,
            )
        return int(v)

    if "S" in words:
        new = ident("S")
        if st.object_id is not None:
            out.append(ObjectEnd(line, st.objects.get(st.object_id, str(st.object_id))))
            st.object_id = None
        if new >= 0:
            name = str(new)
            if new not in st.objects or "A" in words:
                st.objects[new] = name
                out.append(ObjectDefine(line, name, None, words.get("A", "")))
            st.object_id = new
            out.append(ObjectStart(line, name))
    elif "A" in words and st.object_id is not None:
        out.append(ObjectDefine(line, str(st.object_id), None, words["A"]))
    if "P" in words:
        out.append(CancelObject(line, str(ident("P"))))
    if "C" in words and st.object_id is not None:
        out.append(CancelObject(line, str(st.object_id)))
    if "U" in words:
        out.append(UnknownCommand(line, "M486 U", False, f"M486 {text}".strip()))
    return out


def exclude_object_command(
    word: str, params: dict[str, str], line: int, st: ModalState, fail: Fail
) -> list[ProgramItem]:
    """Klipper's EXCLUDE_OBJECT_DEFINE / _START / _END and EXCLUDE_OBJECT."""
    name = params.get("NAME", "").upper()
    if word == "EXCLUDE_OBJECT_DEFINE":
        if not name:
            fail("EXCLUDE_OBJECT_DEFINE without NAME=")
        return [ObjectDefine(line, name, _center(params.get("CENTER"), st), "")]
    if word == "EXCLUDE_OBJECT_START":
        if not name:
            fail("EXCLUDE_OBJECT_START without NAME=")
        return [ObjectStart(line, name)]
    if word == "EXCLUDE_OBJECT_END":
        return [ObjectEnd(line, name)]
    # EXCLUDE_OBJECT: NAME= cancels one; CURRENT=1 the one being printed; no arguments lists them
    if name:
        return [CancelObject(line, name)]
    if params.get("CURRENT") == "1":
        return [CancelObject(line, "")]  # resolved by exclude_objects: the current object
    return []


def _center(text: str | None, st: ModalState) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        return None
    return (x * st.scale + float(st.off[0]), y * st.scale + float(st.off[1]))


def exclude_objects(
    items: Iterable[ProgramItem],
    cancelled: Iterable[str] = (),
    home: tuple[float, float, float] | None = None,
) -> Iterator[ProgramItem]:
    """``items`` without the moves of cancelled objects.

    ``cancelled``: object names or labels (case-insensitive); the file's own
    `CancelObject` records add to them. Moves outside every object are kept.
    ``home``: where the program starts and G28 goes (G-code frame), if known.
    """
    wanted = {c.upper() for c in cancelled}
    labels: dict[str, str] = {}
    current: str | None = None
    skipping = False
    gap = Gap(position=None if home is None else np.asarray(home, dtype=float))

    def is_cancelled(name: str) -> bool:
        return name.upper() in wanted or labels.get(name, "").upper() in wanted

    for item in items:
        match item:
            case MoveChunk():
                if skipping:
                    gap.drop(item)
                else:
                    yield from gap.keep(item)
                continue
            case ObjectDefine(name=name, label=label):
                if label:
                    labels[name] = label
            case ObjectStart(name=name):
                current = name
                skipping = is_cancelled(name)
            case ObjectEnd():
                current, skipping = None, False
            case CancelObject(name=name):
                name = name or (current or "")
                if name:
                    wanted.add(name.upper())
                    skipping = skipping or name == current
            case HomeCommand():
                gap.moved_to(None if home is None else np.asarray(home, dtype=float))
        yield item


def object_names(items: Iterable[ProgramItem]) -> list[str]:
    """Names of the objects a program defines or starts, in order of appearance."""
    seen: dict[str, None] = {}
    for item in items:
        match item:
            case ObjectDefine(name=name) | ObjectStart(name=name):
                seen.setdefault(name, None)
            case _:
                pass
    return list(seen)
