"""`cdprhost calibrate plan` and `calibrate identify` on sessions in several take formats."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from cdprhost.calibration.plan_files import read_plan_csv
from cdprhost.cli.main import main
from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.profile import load_profile
from cdprhost.sim.measurement import achieved_points, perturbed_geometry, simulate_observations
from cdprhost.sim.synthetic_session import write_synthetic_session


def test_plan_writes_poses_and_indices(tmp_path, sim_model, capsys):
    out, rep = tmp_path / "poses.csv", tmp_path / "plan.json"
    code = main(
        [
            "calibrate",
            "plan",
            "--profile",
            "paper-simulation",
            "--poses",
            "5",
            "--check-poses",
            "2",
            "--out",
            str(out),
            "--json",
            str(rep),
            "--restarts",
            "2",
        ]
    )
    assert code == 0
    data = json.loads(rep.read_text())
    assert np.array(data["poses"]).shape == (7, 3) and data["roles"].count("check") == 2
    assert set(data["indices"]) == {"O1", "O2", "O3", "O4", "O5"} == set(data["table1_indices"])
    assert all(data["indices"][k] > data["table1_indices"][k] for k in data["indices"])
    rows = list(csv.DictReader(open(out)))
    assert [r["pose"] for r in rows] == [str(i) for i in range(1, 8)]
    np.testing.assert_allclose(
        [[float(r[c]) for c in "xyz"] for r in rows], data["poses"], atol=1e-5
    )
    plan = read_plan_csv(out, sim_model)
    assert plan.roles == tuple(data["roles"]) and (plan.directions == -1).all()
    assert "Table 1" in capsys.readouterr().out


def test_plan_rejects_fewer_than_four_poses(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(
            [
                "calibrate",
                "plan",
                "--profile",
                "paper-simulation",
                "--poses",
                "3",
                "--out",
                str(tmp_path / "p.csv"),
            ]
        )
    assert exc.value.code == 2 and "at least 4" in capsys.readouterr().err


@pytest.fixture(scope="module")
def session_case(sim_model, plan12):
    truth = sim_model.with_geometry(
        perturbed_geometry(sim_model.geometry, np.random.default_rng(21))
    )
    obs = simulate_observations(
        truth, sim_model, plan12.poses, noise_mm=0.0, rng=np.random.default_rng(22)
    )
    return truth, obs


def write_session(path, obs, poses, fmt, **options):
    return write_synthetic_session(
        path,
        obs.measured,
        poses,
        obs.sliders,
        obs.t_s,
        obs.directions,
        "paper-simulation",
        format=fmt,
        noise_mm=0.05,
        seed=3,
        **options,
    )


@pytest.mark.parametrize(
    "fmt,options",
    [
        ("motive-csv", {"writer_options": {"units": "Meters", "version": "1.23"}}),
        (
            "motive-csv",
            {"writer_options": {"units": "Millimeters", "version": "1.25"}, "gaps_fraction": 0.05},
        ),
        ("motive-csv", {"writer_options": {"units": "Centimeters", "version": "1.21"}}),
        ("vicon-csv", {}),
        ("qualisys-tsv", {}),
    ],
)
def test_identify_recovers_a_machine_at_the_noise_floor(
    tmp_path, sim_model, plan12, session_case, fmt, options
):
    truth, obs = session_case
    session = write_session(tmp_path / "s", obs, plan12.poses, fmt, **options)
    out, rep = tmp_path / "cal.toml", tmp_path / "r.json"
    code = main(
        [
            "calibrate",
            "identify",
            str(session),
            "--profile",
            "paper-simulation",
            "--out",
            str(out),
            "--json",
            str(rep),
        ]
    )
    assert code == 0
    data = json.loads(rep.read_text())
    assert data["poses_used"] == 12 and data["rms_before_mm"] > 1.0 and data["rms_after_mm"] < 0.12
    assert np.array(data["stderr"]["outlets"]).shape == (3, 3) and data["iterations"] >= 1
    cal = MachineModel.from_profile(load_profile(out))
    grid = workspace_grid(sim_model)
    err = np.linalg.norm(
        achieved_points(truth.with_geometry(truth.geometry), cal, grid) - grid, axis=1
    )
    assert (
        np.sqrt(np.mean(err**2)) < 0.12
    )  # workspace error at the noise floor (0.05 mm per coordinate)


def test_identify_uses_role_column_for_check_poses(tmp_path, plan4, session_case, sim_model):
    truth = session_case[0]
    obs = simulate_observations(truth, sim_model, plan4.poses, noise_mm=0.0)
    session = write_session(tmp_path / "s", obs, plan4.poses, "motive-csv")
    rows = list(csv.reader(open(session / "poses.csv")))
    rows[0].append("role")
    for r, role in zip(rows[1:], plan4.roles):
        r.append(role)
    with open(session / "poses.csv", "w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    rep = tmp_path / "r.json"
    args = ["calibrate", "identify", str(session), "--profile", "paper-simulation"]
    args += ["--out", str(tmp_path / "c.toml"), "--json", str(rep)]
    # the session's takes carry a 0.05 mm static offset each that no take shows: the check
    # poses disagree with the take noise alone...
    assert main([*args, "--no-refine"]) == 1
    data = json.loads(rep.read_text())
    assert data["verification"]["verdict"] == "inconsistent" and not data["ok"]
    assert not (tmp_path / "c.toml").exists()
    # ...and agree once that noise is declared: verified on the check poses, then kept
    assert main([*args, "--no-refine", "--noise-floor", "0.05"]) == 0
    data = json.loads(rep.read_text())
    assert (
        data["poses_used"] == 4 and data["check_rms_after_mm"] < 0.6 < data["check_rms_before_mm"]
    )
    assert data["verification"]["verdict"] == "consistent" and not data["verification"]["refined"]
    # by default the check poses then join the fit
    assert main([*args, "--noise-floor", "0.05"]) == 0
    data = json.loads(rep.read_text())
    v = data["verification"]
    assert data["poses_used"] == 6 and v["refined"] and len(v["checks"]) == 2
    assert v["workspace_refined"]["rms_mm"] < v["workspace_fit_only"]["rms_mm"]


def test_invalid_sessions_give_clear_errors(tmp_path, plan12, session_case, capsys):
    truth, obs = session_case
    args = ["--profile", "paper-simulation", "--out", str(tmp_path / "c.toml")]
    assert main(["calibrate", "identify", str(tmp_path / "nope"), *args]) == 2
    assert "no such directory" in capsys.readouterr().err

    session = write_session(tmp_path / "s", obs, plan12.poses, "motive-csv")
    text = (session / "poses.csv").read_text().splitlines()
    fields = text[3].split(",")
    fields[3] = "abc"  # x_cmd of the third pose (file line 4)
    bad = text[:3] + [",".join(fields)] + text[4:]
    (session / "poses.csv").write_text("\n".join(bad) + "\n")
    assert main(["calibrate", "identify", str(session), *args]) == 2
    err = capsys.readouterr().err
    assert "poses.csv" in err and "line 4" in err and "x_cmd" in err

    broken = tmp_path / "b"
    shutil.copytree(session, broken)
    (broken / "poses.csv").write_text("\n".join(text) + "\n")
    (broken / "session.toml").write_text(
        (broken / "session.toml").read_text().replace('"Base:F3"', '"Base:F9"')
    )
    assert main(["calibrate", "identify", str(broken), *args]) == 2
    err = capsys.readouterr().err
    assert "no usable take" in err and "Base:F9" in err

    few = tmp_path / "few"
    write_session(few, obs.subset(np.arange(3)), plan12.poses[:3], "vicon-csv")
    assert main(["calibrate", "identify", str(few), *args]) == 1
    assert "at least 4" in capsys.readouterr().err
    assert not (tmp_path / "c.toml").exists()
