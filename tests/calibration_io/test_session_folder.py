"""Session folder: session.toml and poses.csv validation, measuring, writing, resuming."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from cdprhost.calibration.mocap.readers import FORMATS
from cdprhost.calibration.poses import POSE_COLUMNS, read_poses
from cdprhost.calibration.session import load_session, load_session_config
from cdprhost.calibration.session_writer import SessionWriter, session_toml
from cdprhost.errors import InputError
from cdprhost.sim.synthetic_session import (
    synthesize_take,
    synthetic_config,
    write_synthetic_session,
)
from tests.calibration_io.helpers import DATA, SAMPLE_POINT, SPEC_SESSION_TOML


def pose_arrays(k: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-80, 80, (k, 3)) + [0, 0, 220]
    commanded = points + rng.normal(0, 2, (k, 3))
    s_cmd = rng.uniform(-150, 30, (k, 3))
    t_s = np.arange(k) * 31.25
    dirs = rng.choice([-1, 0, 1], (k, 3))
    return points, commanded, s_cmd, t_s, dirs


@pytest.mark.parametrize("fmt", FORMATS)
def test_synthetic_session_roundtrip(tmp_path, fmt):
    points, commanded, s_cmd, t_s, dirs = pose_arrays(6, seed=len(fmt))
    write_synthetic_session(
        tmp_path / "s",
        points,
        commanded,
        s_cmd,
        t_s,
        dirs,
        "paper-simulation",
        format=fmt,
        noise_mm=0.0,
        jitter_mm=0.02,
        seed=1,
        n_frames=40,
        gaps_fraction=0.02,
    )
    session = load_session(tmp_path / "s")
    assert (
        session.config.mocap.format == fmt and session.config.session.profile == "paper-simulation"
    )
    m = session.measure()
    assert len(m) == 6 and m.rejected == ()
    np.testing.assert_array_equal(m.pose, np.arange(1, 7))
    np.testing.assert_allclose(m.measured, points, atol=0.02)
    np.testing.assert_allclose(m.commanded, commanded, atol=1e-6)
    np.testing.assert_allclose(m.s_cmd, s_cmd, atol=1e-6)
    np.testing.assert_allclose(m.t_s, t_s, atol=1e-6)
    np.testing.assert_array_equal(m.dirs, dirs)
    assert m.se.shape == (6, 3) and (m.base_fit_rms_mm < 0.1).all()
    obs = m.observations()
    np.testing.assert_allclose(obs.sigma_mm, np.sqrt(np.mean(m.se**2, axis=1)))
    assert len(obs) == 6 and (obs.sigma_mm > 0).all() and (obs.sigma_mm < 0.02).all()


def test_spec_example_folder_assembled_by_hand(tmp_path):
    """The spec's session.toml verbatim, takes from two exporters, poses.csv with an extra column."""
    (tmp_path / "takes").mkdir()
    shutil.copy(DATA / "motive_1.25_parent_mm.csv", tmp_path / "takes" / "a.csv")
    shutil.copy(DATA / "vicon_nexus_crlf.csv", tmp_path / "takes" / "b.csv")
    shutil.copy(DATA / "motive_1.23_meters_rigidbody.csv", tmp_path / "takes" / "c.csv")
    (tmp_path / "session.toml").write_text(SPEC_SESSION_TOML)
    (tmp_path / "poses.csv").write_text(
        "take,pose,note,t_s,x_cmd,y_cmd,z_cmd,s1_cmd,s2_cmd,s3_cmd,dir1,dir2,dir3\n"
        "takes/a.csv,1,first,0,12,-20,180,-10.5,-11,-12,1,-1,0\n"
        "\n"
        "takes/b.csv,2,,30.5,12,-20,180,-10.5,-11,-12,+1,-1,0\n"
        "takes/c.csv,3,,61,12,-20,180,-10.5,-11,-12,-1,-1,1\n"
    )
    m = load_session(tmp_path).measure()
    np.testing.assert_allclose(m.measured, np.tile(SAMPLE_POINT, (3, 1)), atol=0.05)
    np.testing.assert_array_equal(m.dirs, [[1, -1, 0], [1, -1, 0], [-1, -1, 1]])
    assert any("file is vicon-csv" in w for w in m.takes[1].warnings)


def test_rejected_and_unreadable_takes_are_listed_not_used(tmp_path):
    points, commanded, s_cmd, t_s, dirs = pose_arrays(4)
    root = write_synthetic_session(
        tmp_path / "s", points, commanded, s_cmd, t_s, dirs, "p", n_frames=20, seed=3
    )
    bad = synthesize_take(points[1], n_frames=20, base_error_mm=3.0, rng=np.random.default_rng(0))
    from cdprhost.calibration.mocap.readers import write_take

    write_take(root / "takes" / "pose_0002.csv", bad, "motive-csv")
    (root / "takes" / "pose_0004.csv").write_text("garbage\n")
    session = load_session(root)
    m = session.measure()
    np.testing.assert_array_equal(m.pose, [1, 3])
    assert [(r.pose, r.reason) for r in m.rejected] == [(2, "base-fit"), (4, "unreadable")]
    assert "pose_0002.csv" in m.rejected[0].message
    with pytest.raises(
        InputError, match=r"pose 2 \(poses.csv line 3\): .*pose_0002.csv: base-marker fit RMS"
    ):
        session.measure(strict=True)


def test_writer_resumes_and_continues_numbering(tmp_path):
    points, commanded, s_cmd, t_s, dirs = pose_arrays(5)
    root = tmp_path / "s"
    write_synthetic_session(
        root, points[:3], commanded[:3], s_cmd[:3], t_s[:3], dirs[:3], "p", n_frames=15, seed=1
    )
    writer = SessionWriter(root)  # resume: configuration read from the folder
    assert writer.next_pose == 4
    write_synthetic_session(
        root, points[3:], commanded[3:], s_cmd[3:], t_s[3:], dirs[3:], "p", n_frames=15, seed=2
    )
    table = read_poses(root / "poses.csv")
    np.testing.assert_array_equal(table.pose, [1, 2, 3, 4, 5])
    assert table.take[3] == "takes/pose_0004.csv"
    np.testing.assert_allclose(
        load_session(root).measure().measured, points, atol=0.3
    )  # noise_mm 0.05
    with pytest.raises(InputError, match="session.toml differs"):
        SessionWriter(root, synthetic_config("another-profile"))
    with pytest.raises(InputError, match="needs its configuration"):
        SessionWriter(tmp_path / "empty")


def test_writer_keeps_poses_readable_when_a_take_fails(tmp_path):
    writer = SessionWriter(tmp_path, synthetic_config("p", "vicon-csv"))
    take = synthesize_take([0, 0, 200], n_frames=12, rng=np.random.default_rng(0))
    assert writer.add_take(take, t_s=0, commanded=[0, 0, 200], s_cmd=[1, 2, 3], dirs=[1, 1, 1]) == 1
    before = (tmp_path / "poses.csv").read_text()
    with pytest.raises(TypeError):
        writer.add_take(
            take, t_s=1, commanded=[0, 0, 200], s_cmd=[1, 2, 3], dirs=[1, 1, 1], bogus_option=1
        )
    with pytest.raises(InputError, match="does not exist"):
        writer.append(
            take="takes/nothing.csv", t_s=1, commanded=[0, 0, 0], s_cmd=[0, 0, 0], dirs=[0, 0, 0]
        )
    assert (tmp_path / "poses.csv").read_text() == before
    assert not [p for p in tmp_path.rglob("*.tmp")]  # no half-written files left behind
    assert (
        writer.add_take(take, t_s=2, commanded=[0, 0, 200], s_cmd=[1, 2, 3], dirs=[-1, 0, 1]) == 2
    )
    assert (tmp_path / "takes" / "pose_0002.csv").is_file()


def test_writer_appends_under_a_hand_made_header(tmp_path):
    (tmp_path / "session.toml").write_text(SPEC_SESSION_TOML)
    (tmp_path / "takes").mkdir()
    shutil.copy(DATA / "motive_1.25_parent_mm.csv", tmp_path / "takes" / "a.csv")
    header = "note," + ",".join(reversed(POSE_COLUMNS))
    (tmp_path / "poses.csv").write_text(
        header + "\nhello,0,0,0,0,0,0,1,2,3,0,takes/a.csv,7"
    )  # no final newline
    writer = SessionWriter(tmp_path)
    assert writer.next_pose == 8
    writer.append(
        take="takes/a.csv",
        t_s=5,
        commanded=[1, 2, 3],
        s_cmd=[4, 5, 6],
        dirs=[1, 0, -1],
        extra={"note": "x"},
    )
    table = read_poses(tmp_path / "poses.csv")
    np.testing.assert_array_equal(table.pose, [7, 8])
    np.testing.assert_allclose(table.commanded[1], [1, 2, 3])
    assert (tmp_path / "poses.csv").read_text().splitlines()[2].startswith("x,")


def test_session_toml_roundtrip_and_spec_layout(tmp_path):
    config = synthetic_config("paper-simulation", "qualisys-tsv")
    text = session_toml(config)
    assert '"Base:F1" = [0.0, 300.0, 0.0]' in text and "acceptance" not in text
    (tmp_path / "session.toml").write_text(text)
    assert load_session_config(tmp_path / "session.toml") == config
    noisy = config.model_copy(update={"mocap": config.mocap.model_copy(update={"noise_mm": 0.07})})
    (tmp_path / "noisy.toml").write_text(session_toml(noisy))
    assert load_session_config(tmp_path / "noisy.toml").mocap.noise_mm == 0.07
    (tmp_path / "spec.toml").write_text(SPEC_SESSION_TOML)
    spec = load_session_config(tmp_path / "spec.toml")
    assert (
        spec.mocap.effector.offset == (0.0, 0.0, -12.0)
        and spec.mocap.acceptance.max_base_rms_mm == 0.5
    )


@pytest.mark.parametrize(
    "edit,problem",
    [
        (
            lambda t: t.replace(
                '"Base:F3" = [259.8, -150.0, 0.0]', '"Base:F3" = [259.8, 750.0, 0.0]'
            ),
            "collinear",
        ),
        (lambda t: t.replace('"Base:F3" = [259.8, -150.0, 0.0]\n', ""), "at least 3 base markers"),
        (lambda t: t.replace('format = "motive-csv"', 'format = "fbx"'), "mocap.format"),
        (lambda t: t.replace("offset =", "ofset ="), "mocap.effector.ofset: unknown key"),
        (
            lambda t: t.replace('profile = "paper-simulation"', ""),
            "session.profile: missing required key",
        ),
        (lambda t: t.replace('"EE:E3"]', '"Base:F1"]'), "Base:F1 listed both"),
        (
            lambda t: t + "\n[mocap.acceptance]\nmax_base_rms_mm = -1\n",
            "mocap.acceptance.max_base_rms_mm",
        ),
        (lambda t: t.replace("[mocap]", "[mocap]\nnoise_mm = 0"), "mocap.noise_mm"),
        (lambda t: t.replace("[mocap]", "[mocap"), "not valid TOML"),
    ],
)
def test_session_toml_errors(tmp_path, edit, problem):
    path = tmp_path / "session.toml"
    path.write_text(edit(SPEC_SESSION_TOML))
    with pytest.raises(InputError, match="session.toml") as err:
        load_session_config(path)
    assert problem in str(err.value) and err.value.exit_code == 2


GOOD_ROW = "1,takes/a.csv,0,1,2,3,4,5,6,1,-1,0"


@pytest.mark.parametrize(
    "text,message",
    [
        ("pose,take,t_s\n", "line 1: header lacks column(s) x_cmd, y_cmd"),
        (
            GOOD_ROW.replace(",2,3,", ",two,3,"),
            "line 2, column 'y_cmd' (column 5): not a number: 'two'",
        ),
        (
            GOOD_ROW.replace("1,-1,0", "2,-1,0"),
            "line 2, column 'dir1' (column 10): must be +1, -1 or 0",
        ),
        (GOOD_ROW.replace("takes/a.csv", ""), "line 2, column 'take' (column 2): empty"),
        (GOOD_ROW.replace(",0,1,2", ",nan,1,2"), "column 't_s' (column 3): not a finite number"),
        (
            GOOD_ROW + "\n" + GOOD_ROW,
            "line 3, column 'pose' (column 1): pose 1 already given on line 2",
        ),
        (GOOD_ROW.replace("1,takes", "0,takes"), "must be >= 1"),
    ],
)
def test_poses_csv_errors_name_line_and_column(tmp_path, text, message):
    path = tmp_path / "poses.csv"
    path.write_text(
        text if text.startswith("pose,take,t_s\n") else ",".join(POSE_COLUMNS) + "\n" + text + "\n"
    )
    with pytest.raises(InputError) as err:
        read_poses(path)
    assert message in str(err.value) and "poses.csv" in str(err.value)


def test_load_session_requires_both_files(tmp_path):
    with pytest.raises(InputError, match="no such directory"):
        load_session(tmp_path / "nope")
    (tmp_path / "session.toml").write_text(SPEC_SESSION_TOML)
    with pytest.raises(InputError, match="missing poses.csv"):
        load_session(tmp_path)
    (tmp_path / "poses.csv").write_text(",".join(POSE_COLUMNS) + "\n")
    m = load_session(tmp_path).measure()
    assert len(m) == 0 and m.measured.shape == (0, 3)


@pytest.mark.parametrize(
    "take,why",
    [
        ("../../etc/passwd", "leads outside the session folder ('..')"),
        ("takes/../../x.csv", "leads outside the session folder"),
        ("/etc/passwd", "is an absolute path"),
        ("C:\\\\Users\\\\me\\\\take.csv", "is an absolute path"),
        ("\\\\\\\\server\\\\share\\\\t.csv", "is an absolute path"),
    ],
)
def test_take_paths_stay_inside_the_session_folder(tmp_path, take, why):
    (tmp_path / "session.toml").write_text(SPEC_SESSION_TOML)
    (tmp_path / "poses.csv").write_text(
        ",".join(POSE_COLUMNS)
        + "\n"
        + GOOD_ROW
        + "\n"
        + GOOD_ROW.replace("1,takes/a.csv", f"2,{take}")
        + "\n"
    )
    with pytest.raises(InputError) as err:
        load_session(tmp_path)
    text = str(err.value)
    assert "poses.csv: line 3, column 'take' (column 2)" in text and why in text
    assert err.value.exit_code == 2


def test_a_link_out_of_the_folder_is_refused_and_windows_separators_work(tmp_path):
    outside = tmp_path / "outside.csv"
    shutil.copy(DATA / "motive_1.25_parent_mm.csv", outside)
    root = tmp_path / "s"
    (root / "takes").mkdir(parents=True)
    (root / "takes" / "link.csv").symlink_to(outside)
    shutil.copy(DATA / "motive_1.25_parent_mm.csv", root / "takes" / "a.csv")
    (root / "session.toml").write_text(SPEC_SESSION_TOML)
    (root / "poses.csv").write_text(
        ",".join(POSE_COLUMNS) + "\n" + GOOD_ROW.replace("takes/a.csv", "takes\\\\a.csv") + "\n"
    )
    session = load_session(root)
    assert session.take_path(0) == (root / "takes" / "a.csv").resolve()
    (root / "poses.csv").write_text(
        ",".join(POSE_COLUMNS) + "\n" + GOOD_ROW.replace("takes/a.csv", "takes/link.csv") + "\n"
    )
    with pytest.raises(InputError, match="outside the session folder"):
        load_session(root)


def test_roles_and_extra_columns_are_read_once(tmp_path):
    header = ",".join(POSE_COLUMNS) + ",role,plan_pose\n"
    (tmp_path / "poses.csv").write_text(
        header
        + GOOD_ROW
        + ",fit,3\n"
        + GOOD_ROW.replace("1,takes", "2,takes")
        + ",CHECK,4\n"
        + GOOD_ROW.replace("1,takes", "3,takes")
        + ",,\n"
    )
    table = read_poses(tmp_path / "poses.csv")
    assert table.roles == ("fit", "check", "fit") and table.extra["plan_pose"] == ("3", "4", "")
    (tmp_path / "poses.csv").write_text(header + GOOD_ROW + ",spare,1\n")
    with pytest.raises(
        InputError, match=r"line 2, column 'role' \(column 13\): must be fit or check"
    ):
        read_poses(tmp_path / "poses.csv")


def test_unknown_acceptance_keys_are_reported_not_refused(tmp_path):
    (tmp_path / "session.toml").write_text(
        SPEC_SESSION_TOML + "\n[mocap.acceptance]\nmax_drift_mm = 0.1\nspread_limit = 2\n"
    )
    (tmp_path / "poses.csv").write_text(",".join(POSE_COLUMNS) + "\n")
    session = load_session(tmp_path)
    assert session.config.acceptance.max_drift_mm == 0.1
    assert session.warnings and "spread_limit" in session.warnings[0]
