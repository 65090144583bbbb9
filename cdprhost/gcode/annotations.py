"""Slicer comments that matter: layer changes and layer heights.

PrusaSlicer/Slic3r write ``;LAYER_CHANGE`` then ``;Z:<height>``; Cura writes
``;LAYER:<n>``; Simplify3D ``; layer <n>, Z = <height>`` (counted like Cura's). Comments are otherwise ignored (``;TYPE:``, ``;WIDTH:`` ...).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum

import numpy as np

_ANNOTATION = re.compile(rb";[ \t]*(LAYER_CHANGE|LAYER:|Z:|layer \d+, Z = )([^\n]*)")
_COMMENT = re.compile(rb";[^\n]*")
_HASH_LINE = re.compile(rb"(?m)^[ \t]*#[^\n]*")  # Klipper test files and configs


class LayerStyle(Enum):
    """How a file marks its layers: decided by the first block with a layer annotation,
    or by height if an extruding move comes first in a block without annotations."""

    PRUSA = "LAYER_CHANGE"  # ;LAYER_CHANGE (+ ;Z:)
    CURA = "LAYER:"  # ;LAYER:n
    HEIGHT = "z"  # no annotations: a layer starts when an extruding move goes higher


@dataclass(frozen=True, slots=True)
class Annotation:
    """``tag`` is ``LAYER_CHANGE``, ``LAYER:`` or ``Z:``; ``index`` the 0-based line in the block."""

    index: int
    tag: str
    value: float | None


def strip_comments(block: bytes) -> bytes:
    """Remove ``;`` comments and lines starting with ``#`` (newlines stay, so line
    numbers do not move)."""
    if b"#" in block:
        block = _HASH_LINE.sub(b"", block)
    return _COMMENT.sub(b"", block) if b";" in block else block


def scan(block: bytes) -> list[Annotation]:
    """Layer annotations of a block, in order."""
    out: list[Annotation] = []
    line = 0
    pos = 0
    for m in _ANNOTATION.finditer(block):
        start = m.start()
        if not _line_start(block, start):
            continue
        line += block.count(b"\n", pos, start)
        pos = start
        tag = m.group(1).decode()
        if tag.startswith("layer "):  # Simplify3D: "; layer 3, Z = 0.600", counted like Cura's
            tag = "LAYER:"
        out.append(Annotation(line, tag, _number(m.group(2))))
    return out


def _line_start(block: bytes, pos: int) -> bool:
    """Whether only blanks precede ``pos`` on its line (a comment line, not a trailing comment)."""
    start = block.rfind(b"\n", 0, pos) + 1
    return start == pos or not block[start:pos].strip()


def choose_style(annotations: list[Annotation]) -> LayerStyle:
    """PrusaSlicer style wins over Cura style; neither (only ``;Z:``): detect layers by height."""
    tags = {a.tag for a in annotations}
    if "LAYER_CHANGE" in tags:
        return LayerStyle.PRUSA
    if "LAYER:" in tags:
        return LayerStyle.CURA
    return LayerStyle.HEIGHT


def _number(rest: bytes) -> float | None:
    try:
        v = float(rest.strip())
    except ValueError:
        return None
    return v if np.isfinite(v) else None
