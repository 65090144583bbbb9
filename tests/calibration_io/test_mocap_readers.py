"""Take readers: round trips through the writers, hand-written exports, units, gaps, errors."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdprhost.calibration.mocap.readers import (
    EXTENSIONS,
    FORMATS,
    Take,
    detect_format,
    read_take,
    write_take,
)
from cdprhost.calibration.mocap.readers.writers import write_motive
from cdprhost.calibration.mocap.takes import measure_effector
from cdprhost.errors import InputError
from cdprhost.sim.mocap_noise import MocapNoise
from cdprhost.sim.synthetic_session import synthesize_take
from tests.calibration_io.helpers import DATA, SAMPLE_POINT, mocap_config, random_take

# Worst rounding of each writer's text: Motive 6 decimals of the unit, Vicon 5, QTM 3 (mm).
TOL_MM = {
    "Meters": 5.1e-4,
    "Centimeters": 5.1e-5,
    "Millimeters": 5.1e-7,
    "vicon-csv": 5.1e-6,
    "qualisys-tsv": 5.1e-4,
    "c3d": 1e-4,
}


def roundtrip(tmp_path, take: Take, fmt: str, **options) -> Take:
    path = tmp_path / f"take{EXTENSIONS[fmt]}"
    write_take(path, take, fmt, **options)
    return read_take(path)


def assert_same(read: Take, take: Take, tol: float) -> None:
    assert read.marker_names == take.marker_names
    np.testing.assert_array_equal(np.isnan(read.positions), np.isnan(take.positions))
    np.testing.assert_allclose(read.positions, take.positions, atol=tol * (1 + 1e-9), rtol=0)
    np.testing.assert_allclose(read.times_s, take.times_s, atol=1e-5)


@pytest.mark.parametrize("version", ["1.21", "1.22", "1.23", "1.24", "1.25"])
@pytest.mark.parametrize("units", ["Meters", "Centimeters", "Millimeters"])
def test_motive_roundtrip_every_version_and_unit(tmp_path, version, units):
    take = random_take(np.random.default_rng(hash((version, units)) % 2**32))
    read = roundtrip(tmp_path, take, "motive-csv", version=version, units=units)
    assert read.format == "motive-csv" and read.notes == ()
    assert_same(read, take, TOL_MM[units])


def test_motive_rigid_body_columns_before_markers_are_skipped(tmp_path):
    rng = np.random.default_rng(3)
    take = random_take(rng, names=("Base:F1", "EE:E1", "EE:E2", "EE:E3"), gaps=0.2)
    path = tmp_path / "rb.csv"
    write_motive(
        path, take, version="1.25", units="Meters", rigid_bodies={"EE": ["EE:E1", "EE:E2", "EE:E3"]}
    )
    lines = path.read_text().splitlines()
    assert lines[2].split(",")[2] == "Rigid Body" and ",Parent," in path.read_text()
    read = read_take(path)
    # Rigid Body Marker columns repeat the names EE:E1..3 with take-averaged values; only Markers count.
    assert_same(read, take, TOL_MM["Meters"])


@pytest.mark.parametrize(
    "fmt,options",
    [
        ("vicon-csv", {}),
        ("vicon-csv", {"devices_section": True}),
        ("vicon-csv", {"units": "m"}),
        ("qualisys-tsv", {}),
        ("qualisys-tsv", {"zero_gaps": False}),
        ("qualisys-tsv", {"column_header": False}),
        ("c3d", {}),
        ("c3d", {"units": "m"}),
    ],
)
def test_other_formats_roundtrip_with_gaps(tmp_path, fmt, options):
    take = random_take(np.random.default_rng(len(str(options))), n_frames=20, gaps=0.15)
    read = roundtrip(tmp_path, take, fmt, **options)
    assert read.format == fmt
    tol = TOL_MM[fmt] * (1000.0 if options.get("units") == "m" and fmt == "vicon-csv" else 1.0)
    assert_same(read, take, tol if fmt != "c3d" else 2e-4)


def test_vicon_writer_uses_crlf(tmp_path):
    path = tmp_path / "v.csv"
    write_take(path, random_take(np.random.default_rng(0)), "vicon-csv")
    raw = path.read_bytes()
    assert raw.count(b"\r\n") == raw.count(b"\n") > 10


SAMPLES = {
    "motive_1.23_meters_rigidbody.csv": ("motive-csv", 12, 120.0, 7),
    "motive_1.25_parent_mm.csv": ("motive-csv", 12, 100.0, 6),
    "vicon_nexus_crlf.csv": ("vicon-csv", 12, 100.0, 6),
    "qualisys_qtm.tsv": ("qualisys-tsv", 12, 150.0, 6),
}


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_hand_written_samples_read_and_measure(name):
    fmt, frames, rate, markers = SAMPLES[name]
    path = DATA / name
    assert detect_format(path) == fmt
    take = read_take(path)
    assert take.format == fmt and take.positions.shape == (frames, markers, 3)
    np.testing.assert_allclose(np.diff(take.times_s), 1.0 / rate, atol=1e-5)
    # every sample puts a static effector at SAMPLE_POINT in a differently rotated world (mm)
    rename = (lambda n: n.replace(":", "_")) if fmt == "qualisys-tsv" else (lambda n: n)
    m = measure_effector(take, mocap_config(rename))
    np.testing.assert_allclose(m.point, SAMPLE_POINT, atol=0.05)
    assert m.base_fit_rms_mm < 0.1 and m.n_frames_used >= 11


def test_motive_sample_units_and_gaps():
    meters = read_take(DATA / "motive_1.23_meters_rigidbody.csv")
    # first Base:F1 X in the file is 0.929550 m
    assert meters.marker("Base:F1")[0, 0] == pytest.approx(929.550)
    # the solved Rigid Body Marker values are constant; the measured Marker values are not
    assert np.ptp(meters.marker("EE:E1")[:, 0]) > 0.005
    unl = meters.marker("Unlabeled 1021")
    assert np.isnan(unl[4:]).all() and np.isfinite(unl[:4]).all()
    mm = read_take(DATA / "motive_1.25_parent_mm.csv")
    assert (
        np.isnan(mm.positions[5, 4]).all() and np.isfinite(np.delete(mm.positions, 5, axis=0)).all()
    )
    qtm = read_take(DATA / "qualisys_qtm.tsv")
    assert np.isnan(qtm.positions[2, 5]).all()  # written as 0.000 0.000 0.000
    vic = read_take(DATA / "vicon_nexus_crlf.csv")
    assert np.isnan(vic.positions[7, 1]).all() and vic.n_frames == 12  # stops at the blank line


def write(tmp_path, name: str, text: str, newline: str = "\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def motive_text(units="Millimeters", cell="1.5"):
    return (
        f"Format Version,1.23,Take Name,t,Capture Frame Rate,100,Length Units,{units}\n\n"
        ",Type,Marker,Marker,Marker\n,Name,EE:E1,EE:E1,EE:E1\n,ID,1,1,1\n"
        ",,Position,Position,Position\nFrame,Time (Seconds),X,Y,Z\n"
        f"0,0.0,1.0,2.0,3.0\n1,0.01,1.0,{cell},3.0\n"
    )


def test_motive_errors_name_line_column_and_marker(tmp_path):
    with pytest.raises(
        InputError, match=r"bad\.csv: line 9, column 4 \(EE:E1 Y\): not a finite number: 'abc'"
    ) as err:
        read_take(write(tmp_path, "bad.csv", motive_text(cell="abc")))
    assert err.value.exit_code == 2
    with pytest.raises(
        InputError, match=r"line 1, key 'Length Units': unknown length unit 'Furlongs'"
    ):
        read_take(write(tmp_path, "u.csv", motive_text(units="Furlongs")))
    with pytest.raises(InputError, match="no 'Frame,Time"):
        read_take(write(tmp_path, "t.csv", motive_text().split("Frame,")[0]))
    rb_only = motive_text().replace(
        ",Type,Marker,Marker,Marker", ",Type,Rigid Body,Rigid Body,Rigid Body"
    )
    with pytest.raises(InputError, match="no Marker position columns"):
        read_take(write(tmp_path, "rb.csv", rb_only))
    with pytest.raises(InputError, match="marker 'EE:E2' not in take"):
        read_take(write(tmp_path, "ok.csv", motive_text())).marker("EE:E2")


def test_motive_centimeters_scale(tmp_path):
    take = read_take(write(tmp_path, "cm.csv", motive_text(units="Centimeters")))
    np.testing.assert_allclose(take.positions[0, 0], [10.0, 20.0, 30.0])


def test_vicon_and_qualisys_errors(tmp_path):
    vic = "Trajectories\n100\n,,EE:E1,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,x,3\n"
    with pytest.raises(InputError, match=r"line 7, column 4 \(EE:E1 Y\)"):
        read_take(write(tmp_path, "v.csv", vic, "\r\n"))
    with pytest.raises(InputError, match=r"line 2: expected the frame rate"):
        read_take(write(tmp_path, "r.csv", vic.replace("100", "fast")))
    with pytest.raises(InputError, match="unknown length unit 'furlong'"):
        read_take(write(tmp_path, "f.csv", vic.replace(",,mm,mm,mm", ",,furlong,furlong,furlong")))
    qtm = "NO_OF_FRAMES\t2\nFREQUENCY\t100\nMARKER_NAMES\tA\tB\n1\t2\t3\t4\t5\n"
    with pytest.raises(InputError, match=r"line 4: 5 columns for 2 markers"):
        read_take(write(tmp_path, "q.tsv", qtm))
    with pytest.raises(InputError, match="no MARKER_NAMES"):
        read_take(write(tmp_path, "n.tsv", "NO_OF_FRAMES\t2\nFREQUENCY\t100\n1\t2\t3\n"))
    no_col = "NO_OF_FRAMES\t1\nMARKER_NAMES\tA\nFrame\tTime\tA X\tA Y\n1\t0\t1\t2\n"
    with pytest.raises(InputError, match="no column 'A Z' for marker 'A'"):
        read_take(write(tmp_path, "c.tsv", no_col))


def test_unrecognised_unreadable_and_overridden_formats(tmp_path):
    with pytest.raises(InputError, match="unrecognised take format"):
        read_take(write(tmp_path, "x.txt", "hello,world\n"))
    with pytest.raises(InputError, match="cannot read"):
        read_take(tmp_path / "absent.c3d")
    junk = tmp_path / "junk.c3d"
    junk.write_bytes(b"\x02\x50" + bytes(600))
    with pytest.raises(InputError, match="not a readable C3D file"):
        read_take(junk, "c3d")
    with pytest.raises(InputError, match="unknown take format 'fbx'"):
        read_take(junk, "fbx")
    # session says motive, file is Vicon: read as Vicon and say so
    take = read_take(DATA / "vicon_nexus_crlf.csv", "motive-csv")
    assert take.format == "vicon-csv" and "session says motive-csv" in take.notes[-1]


def test_take_validates_shapes():
    with pytest.raises(ValueError):
        Take(("a",), np.zeros((3, 2, 3)), np.zeros(3), "s", "c3d")
    with pytest.raises(ValueError):
        Take(("a", "a"), np.zeros((3, 2, 3)), np.zeros(3), "s", "c3d")
    assert set(FORMATS) == set(EXTENSIONS)


NAME = st.from_regex(r"[A-Za-z][A-Za-z0-9_:\- ]{0,14}[A-Za-z0-9]", fullmatch=True)


@settings(max_examples=40, deadline=None)
@given(
    fmt=st.sampled_from(FORMATS),
    names=st.lists(NAME, min_size=1, max_size=6, unique=True),
    seed=st.integers(0, 2**32 - 1),
    frames=st.integers(1, 30),
    gaps=st.floats(0.0, 0.6),
)
def test_any_names_and_gaps_survive_every_format(fmt, names, seed, frames, gaps):
    take = random_take(np.random.default_rng(seed), n_frames=frames, names=tuple(names), gaps=gaps)
    with tempfile.TemporaryDirectory() as tmp:
        read = roundtrip(Path(tmp), take, fmt)
    assert_same(read, take, {"motive-csv": 5.1e-7, "c3d": 2e-4}.get(fmt, TOL_MM.get(fmt, 0.0)))


def test_c3d_with_a_unit_per_point(tmp_path):
    """Optotrak and others write POINT:UNITS as an array, one unit per point."""
    rng = np.random.default_rng(41)
    units = ["m", "mm", "cm", "mm", "m", "mm"]
    take = synthesize_take(
        SAMPLE_POINT, n_frames=60, rng=rng, path=tmp_path / "pp.c3d", format="c3d", units=units
    )
    back = read_take(tmp_path / "pp.c3d")
    np.testing.assert_allclose(back.positions, take.positions, atol=2e-3)
    assert any("differs between points" in n for n in back.notes)
    m = measure_effector(back, mocap_config())
    np.testing.assert_allclose(m.point, SAMPLE_POINT, atol=0.01)


def test_c3d_without_marker_positions_is_a_clear_error(tmp_path):
    import io
    import warnings

    import c3d

    writer = c3d.Writer(point_rate=100.0, analog_rate=100.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        writer.add_frames(
            [(np.zeros((0, 5), np.float32), np.zeros((2, 1), np.float32)) for _ in range(5)]
        )
        writer.set_analog_labels(["gyro x", "gyro y"])
        buf = io.BytesIO()
        writer.write(buf)
    (tmp_path / "rot.c3d").write_bytes(buf.getvalue())
    with pytest.raises(InputError, match=r"rot\.c3d: no marker positions: .*POINT:USED = 0") as err:
        read_take(tmp_path / "rot.c3d")
    assert err.value.exit_code == 2


@pytest.mark.parametrize(
    ("fmt", "options"),
    [
        ("motive-csv", {"european": True, "units": "Meters"}),
        ("motive-csv", {"european": True, "units": "Millimeters", "version": "1.25"}),
        ("vicon-csv", {"european": True}),
    ],
)
def test_european_exports_semicolons_and_decimal_commas(tmp_path, fmt, options):
    rng = np.random.default_rng(42)
    noise = MocapNoise(jitter_mm=0.1, gap_fraction=0.05, gap_run_frames=6)
    path = tmp_path / "eu.csv"
    take = synthesize_take(
        SAMPLE_POINT, realism=noise, n_frames=120, rng=rng, path=path, format=fmt, **options
    )
    text = path.read_text()
    assert ";" in text.splitlines()[0] or ";" in text.splitlines()[2]
    assert re.search(r";-?\d+,\d+;", text)  # decimal commas
    assert detect_format(path) == fmt
    back = read_take(path)
    assert back.marker_names == take.marker_names
    np.testing.assert_allclose(back.positions, take.positions, atol=1e-3)  # gaps stay NaN
    np.testing.assert_allclose(np.diff(back.times_s), 1 / 120, atol=1e-5)


@pytest.mark.parametrize("fmt", ["motive-csv", "vicon-csv", "qualisys-tsv", "c3d"])
def test_runs_of_gaps_survive_every_format(tmp_path, fmt):
    rng = np.random.default_rng(43)
    noise = MocapNoise(jitter_mm=0.05, gap_fraction=0.08, gap_run_frames=10)
    path = tmp_path / f"g{EXTENSIONS[fmt]}"
    options = {"zero_gaps": False} if fmt == "qualisys-tsv" else {}
    take = synthesize_take(
        SAMPLE_POINT, realism=noise, n_frames=200, rng=rng, path=path, format=fmt, **options
    )
    back = read_take(path)
    np.testing.assert_array_equal(np.isnan(back.positions), np.isnan(take.positions))
    assert np.isnan(take.positions).mean() > 0.03
