"""The CLI contract for profile, ik and fk (run in-process through main())."""

import numpy as np

from cdprhost.cli.main import main
from cdprhost.fileio.csv_arrays import read_columns


def test_version(capsys):
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
    assert "cdprhost" in capsys.readouterr().out


def test_profile_show_and_check(tmp_path, capsys):
    assert main(["profile", "show", "paper-prototype"]) == 0
    shown = capsys.readouterr().out
    assert "253.9" in shown
    good = tmp_path / "good.toml"
    good.write_text(shown)
    assert main(["profile", "check", str(good)]) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text(shown.replace("steps_per_mm = [\n    400.0,", "steps_per_mm = [\n    -400.0,"))
    assert main(["profile", "check", str(bad)]) == 2
    assert "drive.steps_per_mm.0" in capsys.readouterr().err


def test_ik_then_fk_round_trip(tmp_path, sim_model):
    pts = np.array([[0, 0, 330.0], [12.5, -7.5, 200.0], [-30, 20, 111.0]])
    src = tmp_path / "points.csv"
    src.write_text("x,y,z\n" + "\n".join(",".join(map(str, p)) for p in pts) + "\n")
    out = tmp_path / "targets.csv"
    assert main(["ik", "--profile", "paper-simulation", "--in", str(src), "--out", str(out)]) == 0
    table = read_columns(out, ("x", "y", "z", "s1", "s2", "s3", "n1", "n2", "n3"))
    a = np.array(sim_model.geometry.outlets)
    expected = (
        np.sqrt(((pts[:, None, :] - a[None]) ** 2).sum(-1)) - sim_model.geometry.initial_lengths
    )
    np.testing.assert_allclose(table[:, 3:6], expected, atol=1e-6)
    np.testing.assert_array_equal(table[:, 6:9], np.rint(expected * 400))
    back = tmp_path / "back.csv"
    assert main(["fk", "--profile", "paper-simulation", "--in", str(out), "--out", str(back)]) == 0
    np.testing.assert_allclose(read_columns(back, ("x", "y", "z")), pts, atol=1e-6)


def test_ik_refuses_points_outside_and_writes_nothing(tmp_path, capsys):
    src = tmp_path / "points.csv"
    src.write_text("x,y,z\n0,0,200\n0,0,331\n")
    out = tmp_path / "targets.csv"
    assert main(["ik", "--profile", "paper-simulation", "--in", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "row 3" in err and "build_volume" in err
    assert not out.exists() and not list(tmp_path.glob(".targets*"))


def test_ik_bad_csv_names_row_and_column(tmp_path, capsys):
    src = tmp_path / "points.csv"
    src.write_text("x,y,z\n0,0,200\n0,abc,200\n")
    assert (
        main(
            [
                "ik",
                "--profile",
                "paper-simulation",
                "--in",
                str(src),
                "--out",
                str(tmp_path / "o.csv"),
            ]
        )
        == 2
    )
    assert "row 3, column 'y'" in capsys.readouterr().err
