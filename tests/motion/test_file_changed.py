"""A G-code file written again while it is printed (a new slice saved over it, a copy
truncating it) must not print as a shorter part that looks whole: the program's items
check the file against what was prepared, before the first item and after the last."""

from __future__ import annotations

import os

import pytest

from cdprhost.gcode.errors import GcodeError
from cdprhost.motion.prepared import prepare
from cdprhost.profile import load_profile
from tests.e2e.processes import square_part


def test_an_unchanged_file_reads_whole_every_time(tmp_path):
    prepared = prepare(
        square_part(tmp_path / "part.gcode", layers=2), load_profile("paper-prototype")
    )
    assert len(list(prepared.items())) == len(list(prepared.items())) > 10


def test_a_file_written_again_while_read_ends_in_an_error_naming_it(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=2)
    prepared = prepare(gcode, load_profile("paper-prototype"))
    items = prepared.items()
    next(items)
    gcode.write_text("G28\n")  # truncated and written again while printing
    with pytest.raises(GcodeError, match="changed") as err:
        list(items)
    assert str(gcode) in str(err.value)


def test_a_file_changed_after_its_check_stops_before_its_first_item(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=2)
    prepared = prepare(gcode, load_profile("paper-prototype"))
    st = gcode.stat()
    os.utime(gcode, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # saved again, same bytes
    with pytest.raises(GcodeError, match="changed"):
        next(prepared.items())
