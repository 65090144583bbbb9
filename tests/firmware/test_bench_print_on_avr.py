"""bench/print_on_avr.py's ``--from-layer`` and ``--to-layer``: the file a print of layers
N to M starts with (pure; the print itself is a benchmark)."""

from __future__ import annotations

import pytest

from tests.conftest import REPO, load_script

EXAMPLE = REPO / "examples" / "example.gcode"


@pytest.fixture(scope="module")
def bench():
    return load_script(REPO / "bench" / "print_on_avr.py", "print_on_avr")


PRUSA = "G28\nM109 S215\n;LAYER_CHANGE\n;Z:0.2\nG1 X1 E1\n;LAYER_CHANGE\n;Z:0.4\nG1 X2 E1\n"
CURA = ";FLAVOR:Marlin\nG28\n;LAYER:0\nG1 X1 E1\n;LAYER:1\nG1 X2 E1\n;LAYER:2\nG1 X3 E1\n"


def test_the_start_is_kept_and_the_layers_before_n_are_left_out(bench):
    assert bench.from_layer(PRUSA, 2) == "G28\nM109 S215\n;LAYER_CHANGE\n;Z:0.4\nG1 X2 E1\n"
    assert bench.from_layer(PRUSA, 1) == PRUSA
    assert bench.from_layer(CURA, 3) == ";FLAVOR:Marlin\nG28\n;LAYER:2\nG1 X3 E1\n"


def test_the_cups_upper_layers_start_at_its_tenth_layer_change(bench):
    text = EXAMPLE.read_text()
    part = bench.from_layer(text, 10).splitlines()
    start = text.splitlines()[: part.index(";LAYER_CHANGE")]
    assert part[: len(start)] == start and ";Z:2.05" in part[len(start) + 1]
    assert sum(line == ";LAYER_CHANGE" for line in part) == 40 - 9


@pytest.mark.parametrize("layer", [0, 3])
def test_a_layer_the_file_does_not_have_is_refused_by_name(bench, layer):
    with pytest.raises(SystemExit, match=f"--from-layer {layer}: the file has 2 marked layers"):
        bench.from_layer(PRUSA, layer)


def test_to_layer_keeps_the_start_and_layers_n_to_m_only(bench):
    assert bench.from_layer(CURA, 2, 2) == ";FLAVOR:Marlin\nG28\n;LAYER:1\nG1 X2 E1\n"
    assert bench.from_layer(CURA, 1, 3) == CURA
    text = EXAMPLE.read_text()
    part = bench.from_layer(text, 6, 6).splitlines()
    assert sum(line == ";LAYER_CHANGE" for line in part) == 1
    assert set(part) < set(text.splitlines())


@pytest.mark.parametrize("last", [1, 4])
def test_a_to_layer_before_the_first_or_past_the_end_is_refused_by_name(bench, last):
    with pytest.raises(SystemExit, match=f"--to-layer {last}: not between 2 and 3"):
        bench.from_layer(CURA, 2, last)
