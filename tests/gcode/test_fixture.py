"""The real PrusaSlicer file: layers, filament, streaming in bounded memory."""

from __future__ import annotations

import itertools
import tracemalloc

import numpy as np
import pytest

from cdprhost.gcode import HomeCommand, LayerChange, MoveChunk, ProgramSummary, read_program


def simple_filament(path) -> float:
    """Independent count: E fed on lines that move X or Y while extruding (absolute E, G92 resets)."""
    e = 0.0
    total = 0.0
    for raw in open(path, encoding="utf-8"):
        code = raw.split(";", 1)[0].split()
        if not code:
            continue
        words = {w[0]: float(w[1:]) for w in code[1:] if len(w) > 1}
        if code[0] == "G92" and "E" in words:
            e = words["E"]
        elif code[0] in ("G0", "G1") and "E" in words:
            if ("X" in words or "Y" in words) and words["E"] > e:
                total += words["E"] - e
            e = words["E"]
    return total


def z_annotations(path) -> list[float]:
    return [float(line[3:]) for line in open(path, encoding="utf-8") if line.startswith(";Z:")]


@pytest.fixture(scope="module")
def fixture_items(fixture_gcode):
    return list(read_program(fixture_gcode))


def test_layers_from_annotations(fixture_items, fixture_gcode):
    layers = [i for i in fixture_items if isinstance(i, LayerChange)]
    assert len(layers) == 149
    assert [lc.index for lc in layers] == list(range(149))
    assert [lc.z for lc in layers] == z_annotations(fixture_gcode)
    summary = ProgramSummary.of(fixture_items)
    assert summary.layers == 149
    chunks = [i for i in fixture_items if isinstance(i, MoveChunk)]
    layer = np.concatenate([c.layer for c in chunks])
    assert layer.min() == -1 and layer.max() == 148
    assert np.all(np.diff(layer) >= 0)
    # every move's layer agrees with the line -> layer lookup
    line = np.concatenate([c.line for c in chunks])
    probe = np.linspace(0, line.size - 1, 200).astype(int)
    assert [summary.layer_of_line(int(line[k])) for k in probe] == layer[probe].tolist()


def test_filament_matches_independent_count_and_slicer(fixture_items, fixture_gcode):
    summary = ProgramSummary.of(fixture_items)
    assert summary.filament_mm == pytest.approx(simple_filament(fixture_gcode), abs=1e-6)
    assert summary.filament_mm == pytest.approx(
        12173.73, abs=0.01
    )  # "; filament used [mm]" in the file


def test_moves_are_continuous_and_ordered(fixture_items):
    chunks = [i for i in fixture_items if isinstance(i, MoveChunk)]
    start = np.concatenate([c.start for c in chunks])
    end = np.concatenate([c.end for c in chunks])
    homes = [i.line for i in fixture_items if isinstance(i, HomeCommand)]
    line = np.concatenate([c.line for c in chunks])
    assert np.all(np.diff(line) > 0)
    jumps = np.flatnonzero(np.any(start[1:] != end[:-1], axis=1))
    # the only discontinuity is the final G28 (home) before the last moves, if any
    assert all(any(line[j] < h < line[j + 1] for h in homes) for j in jumps)
    e0 = np.concatenate([c.e_start for c in chunks])
    e1 = np.concatenate([c.e_end for c in chunks])
    np.testing.assert_allclose(e0[1:], e1[:-1], atol=1e-9)


def test_small_blocks_give_the_same_program(fixture_items, fixture_gcode):
    small = list(read_program(fixture_gcode, block_bytes=50_000))

    def records(items):
        return [i for i in items if not isinstance(i, MoveChunk)]

    assert records(small) == records(fixture_items)
    a = ProgramSummary.of(small)
    b = ProgramSummary.of(fixture_items)
    assert a.moves == b.moves and a.filament_mm == pytest.approx(b.filament_mm, abs=1e-6)


def _peak_while_reading(lines, chunk_moves: int) -> tuple[int, int, int]:
    tracemalloc.start()
    biggest = 0
    moves = 0
    for item in read_program(lines, chunk_moves=chunk_moves):
        if isinstance(item, MoveChunk):
            biggest = max(biggest, len(item))
            moves += len(item)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak, biggest, moves


def test_streaming_memory_does_not_grow(fixture_gcode):
    lines = open(fixture_gcode, encoding="utf-8").read().splitlines()

    def repeated(n):
        return itertools.chain.from_iterable(itertools.repeat(lines, n))

    peak1, big1, moves1 = _peak_while_reading(repeated(1), 4096)
    peak8, big8, moves8 = _peak_while_reading(repeated(8), 4096)
    assert moves8 == 8 * moves1
    assert big1 <= 4096 and big8 <= 4096
    assert peak8 < 1.5 * peak1  # eight times the input, about the same peak
    assert peak8 < 64e6
