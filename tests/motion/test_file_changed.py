"""A G-code file written again while it is printed (a new slice saved over it, ``cp``
writing it in place) must neither print lines the preflight never checked nor end as a
shorter part that looks whole. A print reads its own copy of the file, made once; a
check without a copy compares the file with what was prepared, before the first item and
after the last."""

from __future__ import annotations

import gc
import hashlib
import os
import tempfile
from pathlib import Path

import pytest

import cdprhost.gcode.file_copy as file_copy
from cdprhost.errors import InputError
from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.items import MoveChunk
from cdprhost.job.runner import PrintJob
from cdprhost.motion.prepared import Setup, prepare
from cdprhost.profile import load_profile
from cdprhost.sim.embedded import open_embedded
from tests.e2e.processes import square_part

PROFILE = load_profile("paper-prototype")


def _moves(items) -> list[tuple[float, ...]]:
    """Every move's end point and line, in order."""
    return [
        (*map(float, end), int(line))
        for item in items
        if isinstance(item, MoveChunk)
        for end, line in zip(item.end, item.line)
    ]


def test_an_unchanged_file_reads_whole_every_time(tmp_path):
    prepared = prepare(square_part(tmp_path / "part.gcode", layers=2), PROFILE)
    assert len(list(prepared.items())) == len(list(prepared.items())) > 10


def test_without_a_copy_a_file_written_again_while_read_ends_in_an_error_naming_it(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=2)
    prepared = prepare(gcode, PROFILE)
    items = prepared.items()
    next(items)
    gcode.write_text("G28\n")  # truncated and written again while printing
    with pytest.raises(GcodeError, match="changed") as err:
        list(items)
    assert str(gcode) in str(err.value)


def test_without_a_copy_a_file_changed_after_its_check_stops_before_its_first_item(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=2)
    prepared = prepare(gcode, PROFILE)
    st = gcode.stat()
    os.utime(gcode, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # saved again, same bytes
    with pytest.raises(GcodeError, match="changed"):
        next(prepared.items())


def test_a_copy_reads_the_bytes_prepared_whatever_happens_to_the_file(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=4)
    original = gcode.read_bytes()
    whole = _moves(prepare(gcode, PROFILE).items())
    assert len(whole) > 20
    prepared = prepare(gcode, PROFILE, copy=True)
    assert prepared.sha256 == hashlib.sha256(original).hexdigest()
    square_part(gcode, layers=1)  # a new slice saved over it before the preflight
    assert _moves(prepared.items()) == whole
    items = prepared.items()
    first = [next(items) for _ in range(3)]
    with open(gcode, "r+b") as fh:  # and written in place mid-print, as cp does
        fh.truncate(0)
        fh.write(b"G28\nG1 X500 Y500\n")
    assert _moves(first + list(items)) == whole


def test_a_copy_with_center_and_retarget_reads_the_copy(tmp_path):
    gcode = square_part(tmp_path / "part.gcode", layers=3)
    setup = Setup(center=True)
    prepared = prepare(gcode, PROFILE, setup=setup, copy=True)
    placement = prepare(gcode, PROFILE, setup=setup).placement
    gcode.write_text("G28\n")
    assert prepared.placement == placement
    assert len(_moves(prepared.items())) > 10


def test_errors_in_a_copy_name_the_users_file_and_line(tmp_path):
    gcode = tmp_path / "bad.gcode"
    gcode.write_text("G28\nG1 X10 Y10 F3000\nG1 X1e999\n")
    prepared = prepare(gcode, PROFILE, copy=True)
    with pytest.raises(GcodeError) as err:
        list(prepared.items())
    assert err.value.path == str(gcode) and err.value.line == 3
    assert prepared.copy is not None and prepared.copy.path not in str(err.value)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(InputError, match="cannot read") as err:
        prepare(tmp_path / "gone.gcode", PROFILE, copy=True)
    assert "gone.gcode" in str(err.value)


def test_what_is_not_a_regular_file_is_refused_before_any_copy(tmp_path):
    for path in (tmp_path, Path("/dev/zero")):
        with pytest.raises(InputError, match="not a regular file") as err:
            prepare(path, PROFILE, copy=True)
        assert str(path) in str(err.value)


def test_a_file_written_while_it_is_copied_is_refused_and_no_copy_is_left(tmp_path, monkeypatch):
    gcode = square_part(tmp_path / "part.gcode", layers=1)
    copies = tmp_path / "copies"
    copies.mkdir()
    stamps = iter([(1, 1, 1), (2, 2, 1)])  # the file's size and time before, then after
    monkeypatch.setattr(file_copy, "file_stamp", lambda path: next(stamps))
    with pytest.raises(InputError, match="changed while it was read") as err:
        file_copy.copy_file(gcode, copies)
    assert str(gcode) in str(err.value)
    assert list(copies.iterdir()) == []


def test_a_copy_is_removed_when_nothing_holds_it_and_not_before(tmp_path):
    prepared = prepare(square_part(tmp_path / "part.gcode", layers=2), PROFILE, copy=True)
    assert prepared.copy is not None
    path = Path(prepared.copy.path)
    items = prepared.items()
    next(items)
    del prepared
    gc.collect()
    assert path.exists()  # the read still going holds it
    list(items)
    del items
    gc.collect()
    assert not path.exists()


def test_a_print_whose_file_is_written_again_mid_print_prints_what_it_checked(
    tmp_path, monkeypatch
):
    """The embedded device; the file written again once the print's preflight is done.
    The print's copy is gone when the job ends."""
    gcode = square_part(tmp_path / "part.gcode", layers=3)
    clean = PrintJob(gcode, PROFILE, open_embedded).run()
    assert clean.status == "completed"
    copies = tmp_path / "copies"
    copies.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(copies))
    made: list[list[Path]] = []

    def factory():
        made.append(list(copies.iterdir()))
        square_part(gcode, layers=1)  # a new slice saved over it
        return open_embedded()

    result = PrintJob(gcode, PROFILE, factory).run()
    assert result.status == "completed"
    assert result.segments == clean.segments > 0
    assert result.final_steps == clean.final_steps
    assert len(made[0]) == 1 and list(copies.iterdir()) == []
