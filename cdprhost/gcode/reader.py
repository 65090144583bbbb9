"""`read_program`: stream a G-code file as move chunks and command records, in file order.

Each block of lines is tokenised and resolved with numpy; Python only visits the
few lines that are not plain moves. Errors name the file, line and column, and are
raised in file order: everything before the offending line has been yielded.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import NoReturn

import numpy as np

from cdprhost.gcode import commands, extended, segment, vocabulary
from cdprhost.gcode.annotations import (
    Annotation,
    LayerStyle,
    choose_style,
    scan,
    strip_comments,
)
from cdprhost.gcode.classify import Classified, Other, Problem, classify
from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.items import (
    CHUNK_FIELDS,
    IgnoredParameters,
    LayerChange,
    MoveChunk,
    ProgramItem,
)
from cdprhost.gcode.line_parser import TEXT_COMMANDS, ParsedLine, find_column, parse_line
from cdprhost.gcode.settings import FirmwareRetraction, ParkPoint
from cdprhost.gcode.source import BLOCK_BYTES, BLOCK_LINES, Block, iter_blocks, source_name
from cdprhost.gcode.state import ModalState
from cdprhost.gcode.tokenize import Tokens, tokenize

Source = str | os.PathLike[str] | Iterable[str | bytes]


def read_program(
    source: Source,
    *,
    arc_tolerance_mm: float = 0.01,
    chunk_moves: int = 65536,
    home_position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    placement: tuple[float, float] = (0.0, 0.0),
    retraction: FirmwareRetraction | None = None,
    park: ParkPoint | None = None,
    filament_diameter_mm: float = 1.75,
    mute: tuple[tuple[int, int], ...] = (),
    start_position: tuple[float, float, float] | None = None,
    name: str | None = None,
    block_bytes: int = BLOCK_BYTES,
    block_lines: int = BLOCK_LINES,
) -> Iterator[ProgramItem]:
    """Yield `MoveChunk` and command records of ``source`` (a path, or an iterable of lines).

    ``home_position``: where G28 (and the start) puts the effector, in the G-code frame.
    ``placement``: X/Y shift of the whole program (``--center``, ``--offset``).
    ``retraction``: what G10/G11 do; ``park``: where M600 parks (None: it only waits).
    ``filament_diameter_mm``: converts volumetric E (mm^3: UltiGCode files, ``M200 S1``).
    ``mute``: line ranges (first, last) whose machine-specific commands (factors, limits,
    firmware retraction, filament change) must not change the state: the blocks
    ``--retarget`` replaces (modes, offsets and positions still count).
    ``start_position``: where the effector is when the program starts (default: home).
    Chunks end at every command record, after ``chunk_moves`` moves and at block ends.
    """
    if not (arc_tolerance_mm > 0 and math.isfinite(arc_tolerance_mm)):
        raise ValueError(f"arc_tolerance_mm must be a positive number, got {arc_tolerance_mm!r}")
    if chunk_moves < 1:
        raise ValueError(f"chunk_moves must be at least 1, got {chunk_moves!r}")
    path = source_name(source, name)
    blocks = iter_blocks(source, path, block_bytes=block_bytes, block_lines=block_lines)
    state = ModalState(
        home=np.asarray(home_position, dtype=float),
        placement=np.asarray(placement, dtype=float),
        retraction=retraction or FirmwareRetraction(),
        park=park,
        filament_diameter_mm=filament_diameter_mm,
        mute=tuple(mute),
    )
    if start_position is not None:
        state.pos[:3] = start_position
    return _read(blocks, path, state, arc_tolerance_mm, chunk_moves)


def _read(
    blocks: Iterator[Block], path: str, st: ModalState, tol: float, chunk_moves: int
) -> Iterator[ProgramItem]:
    for block in blocks:
        if block.first_line == 1 and _ULTIGCODE in block.data[:4096]:  # E in mm^3
            st.volumetric_scale = 1.0 / (np.pi * st.filament_diameter_mm**2 / 4.0)
        yield from _BlockReader(block, path, st, tol, chunk_moves).run()
    if st.pending_layer is not None:
        yield st.pending_layer
        st.pending_layer = None


class _BlockReader:
    """Reads one block against the shared modal state."""

    def __init__(self, block: Block, path: str, st: ModalState, tol: float, chunk_moves: int):
        self.data = block.data
        self.first = block.first_line
        self.path = path
        self.st = st
        self.tol = tol
        self.chunk_moves = chunk_moves
        self._lines: list[bytes] | None = None

    # -- helpers -------------------------------------------------------------
    def text(self, index: int) -> str:
        if self._lines is None:
            self._lines = self.data.split(b"\n")
        return self._lines[index].decode("utf-8", "surrogateescape")

    def error(
        self, index: int, reason: str, letter: str | None = None, occurrence: int = 0
    ) -> GcodeError:
        column = find_column(self.text(index), letter, occurrence) if letter else 0
        return GcodeError(self.path, self.first + index, column, reason)

    # -- the block -----------------------------------------------------------
    def run(self) -> Iterator[ProgramItem]:
        st = self.st
        anns = scan(self.data)
        if st.layer_style is None and anns:  # undecided until annotations or an extruding move
            st.layer_style = choose_style(anns)
        tok = tokenize(strip_comments(self.data))
        texts: dict[int, str] = {}
        ext: list[Other] = []
        slow_error: GcodeError | None = None
        if tok.slow.size:
            tok, texts, ext, slow_error = self._slow_lines(tok)
        cls = classify(tok, self.first, texts, st.motion_mode)
        stop, error = self._first_error(cls, slow_error)
        if error is None:
            st.motion_mode = cls.motion_mode
        events: list[Event] = [(o.index, 1, o) for o in cls.others if o.index < stop]
        events += [(o.index, 1, o) for o in ext if o.index < stop]
        events += [(a.index, 0, a) for a in anns if a.index < stop and self._counts(a)]
        events += [(i, 2, rec) for i, rec in cls.ignored if i < stop]
        events.sort(key=lambda e: (e[0], e[1]))
        rows = cls.rows
        if stop < tok.n_lines:
            rows = rows.part(0, int(np.searchsorted(rows.line, self.first + stop)))
        yield from self._walk(rows, events)
        if error is not None:
            raise error

    def _counts(self, a: Annotation) -> bool:
        style = self.st.layer_style
        if style is LayerStyle.PRUSA:
            return a.tag in ("LAYER_CHANGE", "Z:")
        return style is LayerStyle.CURA and a.tag == "LAYER:"

    def _first_error(
        self, cls: Classified, slow_error: GcodeError | None
    ) -> tuple[int, GcodeError | None]:
        p: Problem | None = cls.problem
        error = None
        if p is not None:
            error = self.error(p.index, p.reason, p.letter, p.occurrence)
        if slow_error is not None and (error is None or slow_error.line < error.line):
            error = slow_error
        if error is None:
            return 1 << 62, None
        return error.line - self.first, error

    def _slow_lines(
        self, tok: Tokens
    ) -> tuple[Tokens, dict[int, str], list[Other], GcodeError | None]:
        """Parse the slow lines exactly; check N numbers; merge their words into ``tok``;
        extended (Klipper) commands are returned apart."""
        lines, letters, values = [], [], []
        texts: dict[int, str] = {}
        ext: list[Other] = []
        error = None
        for index in tok.slow.tolist():
            number = self.first + index
            text = self.text(index)
            found = extended.parse(text, index)
            if found is not None:
                ext.append(found)
                continue
            try:
                parsed = parse_line(
                    text,
                    number,
                    self.path,
                    strict_params=vocabulary.KNOWN,
                    flag_commands=vocabulary.FLAG_COMMANDS,
                )
                self._line_number(parsed, text, number)
            except GcodeError as exc:
                error = exc
                break
            for w in parsed.words:
                lines.append(index)
                letters.append(ord(w.letter))
                values.append(math.nan if w.value is None else w.value)
            if parsed.text is not None:
                texts[index] = parsed.text
        if lines:
            line = np.concatenate([tok.line, np.asarray(lines, dtype=np.int64)])
            order = np.argsort(line, kind="stable")
            letter = np.concatenate([tok.letter, np.asarray(letters, dtype=np.uint8)])[order]
            value = np.concatenate([tok.value, np.asarray(values, dtype=np.float64)])[order]
            tok = Tokens(line[order], letter, value, tok.n_lines, tok.slow)
        return tok, texts, ext, error

    def _line_number(self, parsed: ParsedLine, text: str, number: int) -> None:
        """N words go up by one; ``M110 N<n>`` (or the N of its line) restarts the count."""
        st = self.st
        if parsed.n is not None:
            if st.next_n is not None and parsed.n != st.next_n:
                reason = f"line number N{parsed.n} out of sequence (expected N{st.next_n})"
                raise GcodeError(self.path, number, find_column(text, "N"), reason)
            st.next_n = parsed.n + 1
        if parsed.words and parsed.words[0].raw == "M110":
            reset = next(
                (w.value for w in parsed.words[1:] if w.letter == "N" and w.value is not None), None
            )
            if reset is not None:
                st.next_n = int(reset) + 1

    # -- in-order walk ---------------------------------------------------------
    def _walk(self, rows: segment.Rows, events: list[Event]) -> Iterator[ProgramItem]:
        """Runs of rows between modal commands are resolved at once; events are cut in."""
        row_index = rows.line - self.first
        r0 = 0
        passive: list[Event] = []
        for ev in events:
            match ev:
                case (index, _, Other() as other) if vocabulary.is_modal(other):
                    r1 = int(np.searchsorted(row_index, index))
                    yield from self._run(rows.part(r0, r1), passive)
                    passive, r0 = [], r1
                    yield from self._command(other)
                case _:
                    passive.append(ev)
        yield from self._run(rows.part(r0, len(rows)), passive)

    def _run(self, rows: segment.Rows, events: list[Event]) -> Iterator[ProgramItem]:
        st = self.st
        moves: MoveChunk | None = None
        error = None
        if len(rows):
            layer_lines = np.asarray(
                [
                    self.first + i
                    for i, _, a in events
                    if isinstance(a, Annotation) and a.tag in _LAYER_TAGS
                ],
                dtype=np.int64,
            )
            res = segment.compute(rows, st, self.tol, layer_lines)
            moves, error = res.moves, res.error
            if res.layer_starts:
                events = sorted(
                    events + [(lc.line - self.first, 0, lc) for lc in res.layer_starts],
                    key=lambda e: e[0],
                )
        done = 0
        for index, _, payload in events:
            line = self.first + index
            if error is not None and line >= error[0]:
                break
            if moves is not None:
                cut = int(np.searchsorted(moves.line, line))
                yield from self._chunks(moves, done, cut)
                done = cut
            yield from self._event(index, payload)
        if error is not None:
            if moves is not None:
                cut = int(np.searchsorted(moves.line, error[0]))
                yield from self._chunks(moves, done, cut)
            raise self.error(error[0] - self.first, error[1], "G")
        if moves is not None:
            yield from self._chunks(moves, done, len(moves))

    def _chunks(self, moves: MoveChunk, a: int, b: int) -> Iterator[ProgramItem]:
        if a >= b:
            return
        if self.st.pending_layer is not None:
            yield self.st.pending_layer
            self.st.pending_layer = None
        if a == 0 and b == len(moves) and b <= self.chunk_moves:
            yield moves
            return
        for s in range(a, b, self.chunk_moves):
            e = min(s + self.chunk_moves, b)
            yield MoveChunk(*(getattr(moves, f)[s:e] for f in CHUNK_FIELDS))

    def _event(
        self, index: int, payload: Other | LayerChange | Annotation | IgnoredParameters
    ) -> Iterator[ProgramItem]:
        st = self.st
        match payload:
            case Other():
                yield from self._command(payload)
            case LayerChange():  # detected from heights
                st.layer = payload.index
                yield from self._flush_layer()
                yield payload
            case IgnoredParameters():
                yield replace(payload, line=self.first + index)
            case Annotation(tag="Z:", value=value):
                if st.pending_layer is not None:
                    yield replace(st.pending_layer, z=value)
                    st.pending_layer = None
            case Annotation():
                yield from self._flush_layer()
                st.layer += 1
                st.pending_layer = LayerChange(self.first + index, st.layer, None)

    def _command(self, other: Other) -> Iterator[ProgramItem]:
        line = self.first + other.index

        def fail(reason: str, letter: str | None = None) -> NoReturn:
            if other.word not in reason:
                reason = f"{reason} in {other.word}"
            raise self.error(other.index, reason, letter)

        if other.word in TEXT_COMMANDS and other.text is None:  # e.g. "M117 X5" took the fast path
            text = parse_line(self.text(other.index), line, self.path).text
            other = replace(other, text=text)
        if self.st.mute and other.word in vocabulary.MUTABLE and self.st.muted(line):
            return
        produced = commands.apply(other, line, self.st, fail)
        if produced:
            yield from self._flush_layer()
            yield from produced

    def _flush_layer(self) -> Iterator[ProgramItem]:
        if self.st.pending_layer is not None:
            yield self.st.pending_layer
            self.st.pending_layer = None


_LAYER_TAGS = ("LAYER_CHANGE", "LAYER:")
# (block line index, order on the line, what): commands, layer marks, ignored parameters
Event = tuple[int, int, "Other | Annotation | LayerChange | IgnoredParameters"]
_ULTIGCODE = b";FLAVOR:UltiGCode"
